//! What `dynbvh` does with no arguments: the whole story on one shipped animation. It renders
//! the frames and a GIF, renders the traversal-work heat maps of always-refit against
//! always-rebuild side by side, runs the policy benchmark (as `dynbvh bench` does), writes the
//! report and charts, and prints where everything went with a short summary.

use super::render::{RenderArgs, RenderSummary, execute};
use anyhow::{Context, Result};
use clap::Parser;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::report::frame_bench::{self, Options, RaySpec};
use dynbvh::report::ray_sweep;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The animation the default job shows: a sphere whose triangles fly apart and come back,
/// the worst case for refitting.
const DEFAULT_ANIMATION: &str = "animations/explode.glb";

/// Frames of the animation (2 s at 30 fps).
const FRAMES: usize = 60;

/// The sensor scene of the "refit or rebuild?" sweep: a deforming cloth under moving boxes,
/// scanned by a spinning lidar-like fan.
const SENSOR_ANIMATION: &str = "animations/lidar_cloth.glb";

/// Lidar rays per frame of that sweep, and its frames.
const SENSOR_RAYS: [usize; 4] = [1_000, 10_000, 100_000, 1_000_000];
const SENSOR_FRAMES: usize = 20;

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

/// What the default job renders and measures, and where it writes.
struct Job {
    /// The animation.
    file: PathBuf,
    /// Output folder (`frames/`, `heatmap/` and `bench/` go in it).
    out: PathBuf,
    /// Frames over one loop of the animation.
    frames: usize,
    /// Size of the shaded frames.
    shaded: (u32, u32),
    /// Size of each side of the heat-map comparison.
    heat: (u32, u32),
    /// Camera rays per frame of the policy benchmark (an image of this size).
    bench_rays: (usize, usize),
    /// Lidar rays per frame of the sensor scene's sweep.
    sensor_rays: &'static [usize],
    /// Triangles and passes of the price calibration.
    calibration: (usize, usize),
    /// Triangles of the generated explode animation the policies are also benchmarked on (a
    /// mesh whose updates cost as much as its trace), and its frames.
    generated: (usize, usize),
}

impl Job {
    /// What `dynbvh` with no arguments does.
    fn standard() -> Self {
        let base = base_dir();
        Self {
            file: base.join(DEFAULT_ANIMATION),
            out: base.join("out"),
            frames: FRAMES,
            shaded: (480, 360),
            heat: (320, 240),
            bench_rays: (256, 192),
            sensor_rays: &SENSOR_RAYS,
            calibration: (100_000, 5),
            generated: (100_000, 30),
        }
    }
}

/// A policy's modelled total over the oracle's in `r`, `–` when it did not run.
fn ratio_of(r: &frame_bench::Report, policy: &str) -> String {
    r.policies.iter().find(|p| p.policy == policy).map_or_else(
        || "–".to_owned(),
        |p| format!("{:.3}x", p.oracle_ratio_modelled),
    )
}

/// Runs the default job.
pub fn run() -> Result<()> {
    run_job(&Job::standard(), &mut std::io::stdout().lock())
}

/// Runs `job`, printing where everything went and the summary to `w` (progress goes to
/// standard error).
fn run_job(job: &Job, w: &mut dyn Write) -> Result<()> {
    let t0 = Instant::now();
    let file = &job.file;
    let out = &job.out;
    let file_s = file.to_string_lossy().into_owned();
    let frames_dir = out.join("frames");
    let heat_dir = out.join("heatmap");
    let bench_dir = out.join("bench");
    let frames = job.frames.to_string();
    let shaded_size = format!("{}x{}", job.shaded.0, job.shaded.1);
    let heat_size = format!("{}x{}", job.heat.0, job.heat.1);
    writeln!(
        w,
        "dynbvh default job on {} ({} frames): frames, heat maps, policy benchmark",
        file.display(),
        job.frames
    )?;

    eprintln!("rendering the frames ...");
    let shaded = render(&[
        &file_s,
        "--frames",
        &frames,
        "--size",
        &shaded_size,
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
        &heat_size,
        "--heatmap",
        "--compare",
        "refit,rebuild",
        "--gif",
        "--out",
        &heat_dir.to_string_lossy(),
    ])?;

    eprintln!("benchmarking the policies ...");
    let scene = super::load_scene(file, None)?;
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(job.frames))?;
    let (tris, passes) = job.calibration;
    eprintln!(
        "calibrating prices ({}) ...",
        dynbvh::engine::Prices::calibration_source(tris, passes)
    );
    let opts = Options {
        rays: RaySpec::Size(job.bench_rays.0, job.bench_rays.1),
        trace_repeats: 2,
        prices: dynbvh::engine::Prices::calibrate(tris, passes),
        ..Options::default()
    };
    let report = frame_bench::run(&mut src, &opts, |m| eprintln!("  {m} ..."));
    let table = frame_bench::summary_table(&report);
    let mut charts = super::bench::write_report(&bench_dir, &report, &table)?;

    let (gen_tris, gen_frames) = job.generated;
    eprintln!("benchmarking the policies on a generated explode of {gen_tris} triangles ...");
    let generated =
        dynbvh::anim::generate::generate(dynbvh::anim::generate::Kind::Explode, gen_tris, 1);
    let gen_dir = bench_dir.join(format!("explode_{gen_tris}"));
    std::fs::create_dir_all(&gen_dir).map_err(|e| dynbvh::Error::io(&gen_dir, e))?;
    let gen_file = gen_dir.join("explode.glb");
    std::fs::write(&gen_file, &generated.glb).map_err(|e| dynbvh::Error::io(&gen_file, e))?;
    let gen_scene = super::load_scene(&gen_file, None)?;
    let mut gen_src = GltfSource::new(&gen_scene, Some(0), FrameTimes::Count(gen_frames))?;
    let gen_report = frame_bench::run(
        &mut gen_src,
        &Options {
            rays: RaySpec::Size(128, 128),
            builders: Vec::new(),
            tlas_compare: false,
            ..opts.clone()
        },
        |m| eprintln!("  {m} ..."),
    );
    let gen_table = frame_bench::summary_table(&gen_report);
    let gen_charts = super::bench::write_report(&gen_dir, &gen_report, &gen_table)?;

    eprintln!("refit or rebuild at 1k to 1M lidar rays a frame on the sensor scene ...");
    let sensor = base_dir().join(SENSOR_ANIMATION);
    let sensor_scene = super::load_scene(&sensor, None)?;
    let mut sensor_src = GltfSource::new(&sensor_scene, Some(0), FrameTimes::Count(SENSOR_FRAMES))?;
    let sweep = ray_sweep::run(
        &mut sensor_src,
        &Options {
            trace_repeats: 1,
            ..opts.clone()
        },
        job.sensor_rays,
        RaySpec::Lidar,
        |m| eprintln!("  {m} ..."),
    );
    let sweep_table = ray_sweep::table(&sweep);
    std::fs::write(bench_dir.join("ray_sweep.txt"), &sweep_table)?;
    std::fs::write(
        bench_dir.join("ray_sweep.json"),
        serde_json::to_string_pretty(&sweep)?,
    )?;
    ray_sweep::chart(&sweep)
        .save(&bench_dir.join("ray_sweep"), 960, 540)
        .context("writing chart ray_sweep")?;
    charts.push("ray_sweep");

    // Where everything went.
    writeln!(w)?;
    writeln!(w, "{table}")?;
    writeln!(w, "{gen_table}")?;
    writeln!(w, "{sweep_table}")?;
    writeln!(w, "written:")?;
    writeln!(
        w,
        "  {:<44} {} shaded frames ({shaded_size}, shadow rays) and {}",
        format!("{}/", frames_dir.display()),
        shaded.pngs.len(),
        shaded
            .gif
            .as_ref()
            .and_then(|g| g.file_name())
            .map_or(String::new(), |g| g.to_string_lossy().into_owned())
    )?;
    writeln!(
        w,
        "  {:<44} {} heat maps, refit (left) against rebuild (right), and {}",
        format!("{}/", heat_dir.display()),
        heat.pngs.len(),
        heat.gif
            .as_ref()
            .and_then(|g| g.file_name())
            .map_or(String::new(), |g| g.to_string_lossy().into_owned())
    )?;
    writeln!(
        w,
        "  {:<44} summary.txt, report.json, frames.csv, charts {} (.svg and .png)",
        format!("{}/", bench_dir.display()),
        charts.join(", ")
    )?;
    writeln!(
        w,
        "  {:<44} the same on the generated explode ({gen_tris} triangles): charts {}",
        format!("{}/", gen_dir.display()),
        gen_charts.join(", ")
    )?;

    // The short story.
    writeln!(w)?;
    writeln!(w, "summary:")?;
    let (refit, rebuild) = (&heat.timings[0].1, &heat.timings[1].1);
    if let Some((k, worst)) = refit.iter().enumerate().max_by(|a, b| {
        a.1.counts
            .work_per_pixel()
            .total_cmp(&b.1.counts.work_per_pixel())
    }) && let Some(fresh) = rebuild.get(k)
    {
        writeln!(
            w,
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
        )?;
    }
    let find = |name: &str| report.policies.iter().find(|p| p.policy == name);
    if let (Some(r), Some(b)) = (find("refit"), find("rebuild")) {
        writeln!(
            w,
            "  benchmark (modelled, the same on every run at these prices): always refit {:.1} \
             ms, always rebuild {:.1} ms over {} frames of {} rays; wall clock {:.0} and {:.0} \
             ms{}",
            r.modelled_ms,
            b.modelled_ms,
            report.frames,
            report.rays_per_frame,
            r.total_ms,
            b.total_ms,
            if report.busy {
                " (the machine was busy: wall clock disturbed)"
            } else {
                ""
            }
        )?;
    }
    if let Some(best) = report
        .policies
        .iter()
        .min_by(|a, b| a.modelled_ms.total_cmp(&b.modelled_ms))
    {
        writeln!(
            w,
            "  cheapest policy: {} ({:.1} ms modelled, {} rebuilds, {:.3}x the best schedule in \
             hindsight with {} rebuilds)",
            best.policy,
            best.modelled_ms,
            best.rebuilds,
            best.oracle_ratio_modelled,
            report.oracle_modelled.rebuilds
        )?;
    }
    if let Some(d) = report.policies.iter().find(|p| p.default) {
        writeln!(
            w,
            "  default policy {}: {:.1} ms modelled, {} rebuilds, {:.3}x the oracle",
            d.policy, d.modelled_ms, d.rebuilds, d.oracle_ratio_modelled
        )?;
    }
    if let Some(d) = gen_report.policies.iter().find(|p| p.default) {
        writeln!(
            w,
            "  generated explode of {gen_tris} triangles: default policy {:.3}x the oracle ({} \
             rebuilds against its {}; always-refit {}, always-rebuild {})",
            d.oracle_ratio_modelled,
            d.rebuilds,
            gen_report.oracle_modelled.rebuilds,
            ratio_of(&gen_report, "refit"),
            ratio_of(&gen_report, "rebuild"),
        )?;
    }
    if let (Some(first), Some(last)) = (sweep.rows.first(), sweep.rows.last()) {
        let side = |r: &ray_sweep::RayCountRow| {
            if r.refit_ms <= r.rebuild_ms {
                "refit"
            } else {
                "rebuild"
            }
        };
        writeln!(
            w,
            "  sensor scene {}: {} is cheaper at {} rays a frame, {} at {}; the default within \
             {:.1}% of the oracle at every count (see bench/ray_sweep.png)",
            SENSOR_ANIMATION,
            side(first),
            first.rays,
            side(last),
            last.rays,
            100.0
                * (sweep
                    .rows
                    .iter()
                    .map(|r| r.default_ratio)
                    .fold(1.0, f64::max)
                    - 1.0)
        )?;
    }
    writeln!(
        w,
        "  rendering: {:.0} fps at {shaded_size} with shadow rays (pose, update, normals and \
         tracing; {} triangles)",
        shaded.fps(0),
        shaded.triangles
    )?;
    writeln!(w, "done in {:.1} s", t0.elapsed().as_secs_f64())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::AnimationDecoder;
    use image::codecs::gif::GifDecoder;

    /// The frames and size of an animated GIF.
    fn gif_frames(path: &Path) -> (usize, (u32, u32)) {
        let f = std::io::BufReader::new(std::fs::File::open(path).unwrap());
        let frames = GifDecoder::new(f).unwrap().into_frames().collect_frames();
        let frames = frames.unwrap();
        let size = frames.first().map_or((0, 0), |f| f.buffer().dimensions());
        assert!(frames.iter().all(|f| f.buffer().dimensions() == size));
        (frames.len(), size)
    }

    fn png_size(path: &Path) -> (u32, u32) {
        image::open(path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .to_rgb8()
            .dimensions()
    }

    /// The default job, smaller: every file it says it wrote is there, and the summary names
    /// the folders.
    #[test]
    fn the_default_job_writes_what_it_prints() {
        let out = std::env::temp_dir().join(format!("dynbvh_default_job_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let n = 6;
        let job = Job {
            file: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(DEFAULT_ANIMATION),
            out: out.clone(),
            frames: n,
            shaded: (64, 48),
            heat: (96, 72),
            bench_rays: (48, 36),
            sensor_rays: &[500, 2000],
            calibration: (5_000, 1),
            generated: (2_000, 4),
        };
        let mut printed = Vec::new();
        run_job(&job, &mut printed).unwrap();
        let printed = String::from_utf8(printed).unwrap();

        let (frames, heat, bench) = (out.join("frames"), out.join("heatmap"), out.join("bench"));
        for f in 0..n {
            assert_eq!(
                png_size(&frames.join(format!("frame_{f:04}.png"))),
                (64, 48)
            );
            assert_eq!(
                png_size(&heat.join(format!("compare_{f:04}.png"))),
                (2 * 96 + 4, 72)
            );
        }
        assert!(!frames.join(format!("frame_{n:04}.png")).exists());
        assert_eq!(gif_frames(&frames.join("frame.gif")), (n, (64, 48)));
        assert_eq!(gif_frames(&heat.join("compare.gif")), (n, (2 * 96 + 4, 72)));

        let summary = std::fs::read_to_string(bench.join("summary.txt")).unwrap();
        assert!(
            summary.contains("refit") && summary.contains("rebuild"),
            "{summary}"
        );
        assert!(
            printed.contains(summary.trim()),
            "the table is printed:\n{printed}"
        );
        let csv = std::fs::read_to_string(bench.join("frames.csv")).unwrap();
        assert!(
            csv.lines().count() > n,
            "a header and a row per frame and policy:\n{csv}"
        );
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(bench.join("report.json")).unwrap())
                .unwrap();
        assert_eq!(json["frames"], n);
        assert!(json["policies"].as_array().is_some_and(|p| p.len() >= 2));
        // The charts the summary names, each as SVG and PNG.
        let charts = printed
            .lines()
            .find_map(|l| l.split_once(" charts ").map(|(_, c)| c))
            .and_then(|c| c.strip_suffix(" (.svg and .png)"))
            .unwrap_or_else(|| panic!("the charts are listed:\n{printed}"));
        let stems: Vec<&str> = charts.split(", ").collect();
        assert!(!stems.is_empty());
        for stem in stems {
            let svg = std::fs::read_to_string(bench.join(stem).with_extension("svg")).unwrap();
            assert!(svg.contains("<svg"), "{stem}.svg");
            assert_eq!(
                png_size(&bench.join(stem).with_extension("png")),
                (960, 540)
            );
        }

        // Where everything went, and the short story.
        for dir in [&frames, &heat, &bench] {
            assert!(
                printed.contains(&format!("{}/", dir.display())),
                "{} is named:\n{printed}",
                dir.display()
            );
        }
        for what in [
            "frame.gif",
            "compare.gif",
            "summary:",
            "heat maps: at frame",
            "benchmark (modelled",
            "cheapest policy:",
            "sensor scene",
            "default policy",
            "rendering:",
            "done in",
        ] {
            assert!(printed.contains(what), "{what:?} is printed:\n{printed}");
        }
        let _ = std::fs::remove_dir_all(&out);
    }
}
