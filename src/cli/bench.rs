//! `dynbvh bench`: every refit-or-rebuild policy on the same frames and rays of an animation.

use super::args::{self, Limits, Size};
use anyhow::{Context, Result, bail};
use clap::Args;
use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::{FrameSource, SineSphere, Window};
use dynbvh::engine::{CostMeasure, Policy, Prices, Traversal, WorkerPriority};
use dynbvh::report::frame_bench::{self, Options, RaySpec, Sweep, SweepFailure};
use std::path::{Path, PathBuf};

/// Bytes a camera ray of the benchmark costs: the ray, and each configuration's hit record.
const RAY_BYTES: u64 = 128;

/// Arguments of `bench`.
#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Animated glTF file (.glb/.gltf).
    #[arg(
        required_unless_present_any = ["synthetic", "all"],
        conflicts_with_all = ["synthetic", "all"]
    )]
    file: Option<PathBuf>,
    /// The sweep: every animation of every .glb/.gltf under the `--dir` folders (default
    /// `animations` and `../shared/gltf-samples`), every policy, printing total time over the
    /// oracle's per file, animation and policy, and a conclusion computed from those rows
    /// (default 30 frames and 128x128 rays; no builder points). Files that fail to load are
    /// listed with the reason, and make the exit status non-zero.
    #[arg(long, conflicts_with = "synthetic")]
    all: bool,
    /// Folder searched by `--all` (repeatable).
    #[arg(long = "dir", requires = "all")]
    dirs: Vec<PathBuf>,
    /// Sizes (triangles, e.g. 100k,1m) at which `--all` also generates and runs the explode,
    /// swap, tube and wave animations (the scenes where a tree update costs as much as the
    /// trace); `none` for none. Default 100k,1m (the 1M rows take a few minutes each).
    #[arg(long, requires = "all", value_name = "SIZES", value_parser = generated_sizes)]
    generated: Option<GeneratedSizes>,
    /// Instead of a file: a bumpy sphere of about N triangles deformed by a travelling wave.
    #[arg(long, allow_negative_numbers = true, value_name = "N")]
    synthetic: Option<usize>,
    /// Animation name or index (default: the first).
    #[arg(long, short)]
    animation: Option<String>,
    /// Frames: a count N spread over one loop of the animation (default 60), or a range A..B
    /// (B excluded) of the frames at --fps (default 30), as `render --frames` takes them: the
    /// engines are built at frame A and updated through B - 1. Frames are numbered from 0, the
    /// animation's start, in the tables, CSV and JSON as in every command's output.
    #[arg(long, allow_negative_numbers = true, value_name = "N|A..B")]
    frames: Option<args::FrameSpan>,
    /// Frames per second of animation time instead of a frame count.
    #[arg(long, allow_negative_numbers = true, value_parser = args::frame_rate)]
    fps: Option<f32>,
    /// Rays per frame, from a camera looking at the first frame.
    #[arg(long, allow_negative_numbers = true, conflicts_with = "size",
          value_parser = clap::value_parser!(u64).range(1..=1 << 28))]
    rays: Option<u64>,
    /// Camera image size WxH (default 256x256; sides up to 16384).
    #[arg(long, value_name = "WxH")]
    size: Option<Size>,
    /// Cast the `--rays` (default 65536) of a spinning lidar-like fan above the scene instead of
    /// camera rays; they turn from frame to frame.
    #[arg(long, conflicts_with = "size")]
    lidar: bool,
    /// Policy to run (repeatable): refit, rebuild, periodic:N, threshold:R, amortized,
    /// amortized-plain, the rungs optimize:B and partial:F (shares in (0, 1]), ladder, or async
    /// (rebuilds on a worker thread while the old tree serves).
    /// Default: all of refit, rebuild, periodic:8, threshold:1.3, amortized, amortized-plain.
    #[arg(long = "policy", short)]
    policies: Vec<Policy>,
    /// Directory for summary.txt (the printed table), frames.csv, report.json and the charts
    /// (SVG and PNG); with `--all`, summary.txt and sweep.json.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the report as JSON instead of the table.
    #[arg(long)]
    json: bool,
    /// Skip the oracle (it builds at every frame and refits through the later ones) and the
    /// always-refit and always-rebuild runs it needs (unless asked for with `--policy`).
    #[arg(long)]
    no_oracle: bool,
    /// Also compute the oracle whose moves include the rungs of the policies run (`optimize:B`,
    /// `partial:F`, `ladder`), at most one between two rebuilds. It restructures the tree
    /// built at every frame at every later frame and replays the sample on it through the
    /// rest of the clip: `frames^3 / 6` replays per rung, minutes at 100k triangles.
    #[arg(long)]
    oracle_rungs: bool,
    /// Skip the builder points of the speed-against-accuracy chart (each rebuilds every frame
    /// with one builder, the full sweep included: slow on large meshes).
    #[arg(long)]
    no_builders: bool,
    /// Skip the top-level tree comparison (the default mesh policy run again under each
    /// top-level tree policy).
    #[arg(long)]
    no_tlas_compare: bool,
    /// Do not tell the policies how many frames the run makes: each decides as if the run
    /// went on forever (a rebuild just before the end is then not ruled out).
    #[arg(long)]
    open_ended: bool,
    /// Build each deforming mesh's first tree for the whole clip from this many poses spread
    /// over the frames (`MeshBvh::build_clip_aware`); 0: a plain build of frame 0. The
    /// policies' rebuilds stay plain builds unless `--clip-rebuilds`.
    #[arg(long, allow_negative_numbers = true, default_value_t = 0, value_parser = clap::value_parser!(u64).range(0..=dynbvh::bvh::build::clip::MAX_POSES as u64))]
    clip_aware: u64,
    /// With `--clip-aware K`: every rebuild is clip-aware too, for the pose it is made at and
    /// the sampled poses after it (priced as such; the oracle's rebuilds likewise).
    #[arg(long, requires = "clip_aware")]
    clip_rebuilds: bool,
    /// The scheduling class of `async`'s background worker: `normal`, or `idle` (Linux
    /// `SCHED_IDLE`: it builds on cycles the frame loop leaves, so the frames beside a build
    /// keep their pace; on a machine busy with other work the build may then arrive late, and
    /// the engine waits for it).
    #[arg(long, value_name = "normal|idle", default_value_t = WorkerPriority::Normal)]
    worker_priority: WorkerPriority,
    /// Trace passes per frame, the fastest counting.
    #[arg(long, allow_negative_numbers = true, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=args::MAX_REPEATS))]
    repeats: u64,
    /// Worker threads (default: all cores; more than the cores are capped).
    #[arg(long, allow_negative_numbers = true, value_parser = args::thread_count)]
    threads: Option<usize>,
    /// Mesh trees the rays walk: binary, or wide (8-wide trees kept beside the binary ones).
    #[arg(long, value_name = "binary|wide", default_value_t = Traversal::DEFAULT)]
    traversal: Traversal,
    /// Trace each frame's rays as packets of up to 128 (a camera image in 16x8 tiles; the lidar
    /// fan in its own order), as a renderer does, instead of ray by ray; the ray-work sample
    /// still walks its rays one by one, so the degradation check then tells how well that
    /// measure follows the packets' trace time.
    #[arg(long)]
    packets: bool,
    /// What the policies decide on: rays (the ray-work sample of the frame's own rays) or sah.
    #[arg(long, value_name = "rays|sah", default_value_t = CostMeasure::default())]
    cost: CostMeasure,
    /// Unit prices of the modelled measure, from a file written by `--save-prices` (default: a
    /// calibration pass at the start of the run).
    #[arg(long, value_name = "FILE")]
    prices: Option<PathBuf>,
    /// Write the prices used to this file (JSON), to reuse with `--prices`.
    #[arg(long, value_name = "FILE")]
    save_prices: Option<PathBuf>,
    #[command(flatten)]
    limits: Limits,
}

/// Triangles of the calibration mesh, and passes per price.
const CALIBRATION: (usize, usize) = (100_000, 5);

/// The run's prices: loaded, or calibrated now; printed either way.
fn prices(a: &BenchArgs) -> Result<Prices> {
    let p = match &a.prices {
        Some(f) => {
            let p = Prices::load(f)?;
            eprintln!("prices from {}", f.display());
            p
        }
        None => {
            let (tris, passes) = CALIBRATION;
            eprintln!(
                "calibrating prices ({}) ...",
                Prices::calibration_source(tris, passes)
            );
            Prices::calibrate(tris, passes)
        }
    };
    eprintln!(
        "prices: refit {:.3} ns/triangle, rebuild {:.3} ns/(n log2 n), estimate {:.3} ns/triangle, \
         trace {:.3} ns/node + {:.3} ns/triangle",
        p.refit_ns_per_tri,
        p.rebuild_ns_per_tri_log,
        p.estimate_ns_per_tri,
        p.trace_ns_per_node,
        p.trace_ns_per_tri
    );
    if let Some(f) = &a.save_prices {
        std::fs::write(f, serde_json::to_string_pretty(&p)?)
            .with_context(|| format!("writing {}", f.display()))?;
        eprintln!("wrote {}", f.display());
    }
    Ok(p)
}

/// Runs `bench`.
pub fn run(a: BenchArgs) -> Result<()> {
    args::init_threads(a.threads)?;
    let mut opts = Options {
        trace_repeats: a.repeats as usize,
        oracle: !a.no_oracle,
        oracle_rungs: a.oracle_rungs && !a.no_oracle,
        tlas_compare: !a.no_tlas_compare,
        known_length: !a.open_ended,
        traversal: a.traversal,
        packets: a.packets,
        cost: a.cost,
        prices: prices(&a)?,
        worker: a.worker_priority,
        ..Options::default()
    };
    if a.no_builders {
        opts.builders.clear();
    }
    if !a.policies.is_empty() {
        opts.policies.clone_from(&a.policies);
    }
    opts.rays = match (a.rays, a.size) {
        (n, _) if a.lidar => RaySpec::Lidar(n.map_or(65_536, |n| n as usize)),
        (Some(n), _) => RaySpec::Count(n as usize),
        (None, Some(s)) => RaySpec::Size(s.w as usize, s.h as usize),
        (None, None) => RaySpec::Size(256, 256),
    };
    let ray_count = match opts.rays {
        RaySpec::Count(n) | RaySpec::Lidar(n) => n as u64,
        RaySpec::Size(w, h) => (w * h) as u64,
    };
    let ray_arg = match (a.rays, a.size) {
        (Some(n), _) => format!("--rays {n}"),
        (None, Some(s)) => format!("--size {s}"),
        (None, None) => "the default 256x256 rays".into(),
    };
    a.limits.check_memory(
        &format!("{ray_arg} ({ray_count} rays per frame)"),
        ray_count * RAY_BYTES,
    )?;
    let default_count = FrameTimes::Count(if a.all { 30 } else { 60 });
    let (times, range) = args::timeline(a.frames, a.fps, default_count, &a.limits)?;
    if a.all {
        if a.rays.is_none() && a.size.is_none() {
            opts.rays = RaySpec::Size(128, 128);
        }
        if range.is_some() {
            bail!("--all runs whole animations: give --frames N or --fps, not a range A..B");
        }
        opts.builders.clear();
        return sweep(&a, &opts, times);
    }
    let report = match (&a.file, a.synthetic) {
        (Some(path), _) => {
            let scene = super::load_scene(path, None)?;
            a.limits.memory.check_scene(&scene, args::BENCH_MEMORY, 1)?;
            let anim = args::animation_or_first(&scene, path, a.animation.as_deref())?;
            if anim.is_none() {
                eprintln!(
                    "{}: no animation; every frame is the rest pose",
                    path.display()
                );
            }
            if let (FrameTimes::Fps(fps), None) = (times, range) {
                let d = anim.map_or(0.0, |k| scene.animations[k].duration);
                let n = args::frames_at(d, fps);
                a.limits
                    .check_frames(&format!("--fps {fps} over the animation's {d} s"), n)?;
            }
            let mut src = GltfSource::new(&scene, anim, times)?
                .with_clip_aware(a.clip_aware as usize)
                .with_clip_rebuilds(a.clip_rebuilds);
            run_frames(&mut src, range, &opts)?
        }
        (None, Some(n)) => {
            a.limits.check_memory(
                &format!("--synthetic {n}"),
                (n as u64).saturating_mul(args::BENCH_MEMORY.triangle),
            )?;
            let frames = match (times, range) {
                (_, Some((_, end))) => end,
                (FrameTimes::Count(n), None) => n,
                (FrameTimes::Fps(f), None) => {
                    let n = args::frames_at(1.0, f);
                    a.limits.check_frames(&format!("--fps {f} over 1 s"), n)?;
                    n as usize
                }
            };
            let mut src = SineSphere::new(n, frames, 0.02, 0.15);
            run_frames(&mut src, range, &opts)?
        }
        (None, None) => unreachable!("clap requires one"),
    };
    let table = frame_bench::summary_table(&report);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{table}");
    }
    if let Some(dir) = &a.out {
        write_report(dir, &report, &table)?;
        eprintln!("wrote {}", dir.display());
    }
    check_oracle(std::slice::from_ref(&report))
}

/// Runs the benchmark over `src`, or over its frames `start..end` when `range` is given
/// (the engines built at `start`).
fn run_frames(
    src: &mut dyn FrameSource,
    range: Option<(usize, usize)>,
    opts: &Options,
) -> Result<frame_bench::Report> {
    let progress = |m: &str| eprintln!("  {m} ...");
    let Some((start, end)) = range else {
        eprintln!("{}: {} frames", src.name(), src.frames());
        return Ok(frame_bench::run(src, opts, progress));
    };
    let last = src.frames();
    let mut window = Window::new(src, start, end).with_context(|| {
        format!(
            "--frames {start}..{end}: a range needs at least two frames within the \
             animation's frames 0..{} at this rate",
            last + 1
        )
    })?;
    eprintln!(
        "{}: frames {start}..{end} (built at {start})",
        window.name()
    );
    Ok(frame_bench::run(&mut window, opts, progress))
}

/// Writes what `bench --out` (and the default job) keeps of a run into `dir`: the printed
/// `summary` as summary.txt, frames.csv, report.json and the charts.
pub fn write_report(
    dir: &Path,
    report: &frame_bench::Report,
    summary: &str,
) -> Result<Vec<&'static str>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let write = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
    };
    write("summary.txt", summary)?;
    write("frames.csv", &frame_bench::to_csv(&report.per_frame))?;
    write("report.json", &serde_json::to_string_pretty(report)?)?;
    let mut charts = Vec::new();
    for (stem, chart) in frame_bench::charts(report) {
        chart
            .save(&dir.join(stem), 960, 540)
            .with_context(|| format!("writing chart {stem}"))?;
        charts.push(stem);
    }
    Ok(charts)
}

/// Fails loudly when a policy's modelled total fell below the modelled oracle's, the exact
/// optimum of that measure: a bug in the engine, the oracle or the bench.
fn check_oracle(reports: &[frame_bench::Report]) -> Result<()> {
    let below: Vec<String> = reports
        .iter()
        .flat_map(|r| {
            r.below_oracle
                .iter()
                .map(move |b| format!("{}: {b}", r.source))
        })
        .collect();
    if !below.is_empty() {
        bail!(
            "BELOW THE ORACLE: a policy's modelled total fell below the oracle's, the exact \
             optimum of that measure: {}",
            below.join("; ")
        );
    }
    Ok(())
}

/// Every animated glTF file under `dir`, sorted.
fn gltf_files(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .map(|e| e.map(|e| e.path()))
        .collect::<std::io::Result<_>>()?;
    entries.sort();
    for p in entries {
        if p.is_dir() {
            if p.file_name().is_some_and(|n| n != "_meta") {
                gltf_files(&p, out)?;
            }
        } else if p
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("glb") || e.eq_ignore_ascii_case("gltf"))
        {
            out.push(p);
        }
    }
    Ok(())
}

/// Triangle counts of the generated rows of `bench --all`.
#[derive(Clone, Debug)]
pub struct GeneratedSizes(Vec<usize>);

impl Default for GeneratedSizes {
    fn default() -> Self {
        Self(vec![100_000, 1_000_000])
    }
}

/// Largest generated size `--generated` takes.
const MAX_GENERATED: usize = 4_000_000;

fn generated_sizes(s: &str) -> Result<GeneratedSizes, String> {
    if s.trim().eq_ignore_ascii_case("none") {
        return Ok(GeneratedSizes(Vec::new()));
    }
    s.split(',')
        .map(|t| {
            let t = t.trim().to_ascii_lowercase();
            let (digits, scale) = match t.strip_suffix('k') {
                Some(d) => (d, 1_000),
                None => match t.strip_suffix('m') {
                    Some(d) => (d, 1_000_000),
                    None => (t.as_str(), 1),
                },
            };
            let n = digits
                .parse::<usize>()
                .ok()
                .and_then(|n| n.checked_mul(scale))
                .ok_or_else(|| format!("{t:?}: expected a triangle count such as 100k or 1m"))?;
            if (1_000..=MAX_GENERATED).contains(&n) {
                Ok(n)
            } else {
                Err(format!("{t:?}: from 1k to {MAX_GENERATED} triangles"))
            }
        })
        .collect::<Result<Vec<_>, _>>()
        .map(GeneratedSizes)
}

/// The generated animations of `bench --all`, written under the system's temporary folder
/// (made again on every run: the generator is deterministic).
fn generated_files(sizes: &GeneratedSizes, limits: &Limits) -> Result<Vec<PathBuf>> {
    use dynbvh::anim::generate::{Kind, generate};
    let dir = std::env::temp_dir().join("dynbvh-bench-generated");
    if !sizes.0.is_empty() {
        std::fs::create_dir_all(&dir).map_err(|e| dynbvh::Error::io(&dir, e))?;
    }
    let mut out = Vec::new();
    for &n in &sizes.0 {
        for kind in [Kind::Explode, Kind::Swap, Kind::Tube, Kind::Wave] {
            limits.check_memory(
                &format!("--generated {n}"),
                n as u64 * super::r#gen::bytes_per_triangle(kind),
            )?;
            let path = dir.join(format!("{}_{}.glb", kind.name(), n));
            eprintln!("generating {} ...", path.display());
            let g = generate(kind, n, 1);
            std::fs::write(&path, &g.glb).map_err(|e| dynbvh::Error::io(&path, e))?;
            out.push(path);
        }
    }
    Ok(out)
}

/// `bench --all`: the sweep over every animated file.
fn sweep(a: &BenchArgs, opts: &Options, times: FrameTimes) -> Result<()> {
    let dirs = if a.dirs.is_empty() {
        vec![
            PathBuf::from("animations"),
            PathBuf::from("../shared/gltf-samples"),
        ]
    } else {
        a.dirs.clone()
    };
    let mut files = Vec::new();
    for d in &dirs {
        gltf_files(d, &mut files)?;
    }
    files.extend(generated_files(
        &a.generated.clone().unwrap_or_default(),
        &a.limits,
    )?);
    let mut reports = Vec::new();
    let mut failed = Vec::new();
    let mut not_animated = Vec::new();
    for path in &files {
        let scene = match Scene::load(path) {
            Ok((s, _)) => s,
            Err(e) => {
                eprintln!("{}: FAILED to load: {e}", path.display());
                failed.push(SweepFailure {
                    source: path.display().to_string(),
                    error: format!("failed to load: {e}"),
                });
                continue;
            }
        };
        if scene.animations.is_empty() {
            eprintln!("{}: no animation, not run", path.display());
            not_animated.push(path.display().to_string());
            continue;
        }
        for anim in 0..scene.animations.len() {
            let label = format!(
                "{} [animation {anim}{}]",
                path.display(),
                scene.animations[anim]
                    .name
                    .as_deref()
                    .map_or(String::new(), |n| format!(" {n:?}"))
            );
            if let FrameTimes::Fps(fps) = times {
                let d = scene.animations[anim].duration;
                let n = args::frames_at(d, fps);
                if let Err(e) = a.limits.check_frames(&format!("--fps {fps} over {d} s"), n) {
                    eprintln!("{label}: FAILED: {e}");
                    failed.push(SweepFailure {
                        source: label,
                        error: e.to_string(),
                    });
                    continue;
                }
            }
            let mut src = match GltfSource::new(&scene, Some(anim), times) {
                Ok(s) => s
                    .with_clip_aware(a.clip_aware as usize)
                    .with_clip_rebuilds(a.clip_rebuilds),
                Err(e) => {
                    eprintln!("{label}: FAILED: {e}");
                    failed.push(SweepFailure {
                        source: label,
                        error: e.to_string(),
                    });
                    continue;
                }
            };
            eprintln!("{}: {} frames", src.name(), src.frames());
            // A panic in one row (a bug) is reported as that row's failure; the sweep goes on.
            let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                frame_bench::run(&mut src, opts, |_| {})
            }));
            match run {
                Ok(report) => {
                    eprint!("{}", frame_bench::summary_table(&report));
                    reports.push(report);
                }
                Err(p) => {
                    let why = p
                        .downcast_ref::<String>()
                        .cloned()
                        .or_else(|| p.downcast_ref::<&str>().map(|s| (*s).to_string()))
                        .unwrap_or_else(|| "panicked".into());
                    eprintln!("{label}: FAILED: {why}");
                    failed.push(SweepFailure {
                        source: label,
                        error: format!("panicked: {why}"),
                    });
                }
            }
        }
    }
    let sweep = Sweep::new(reports, failed, not_animated);
    let table = frame_bench::sweep_table(&sweep);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&sweep)?);
    } else {
        print!("{table}");
    }
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        std::fs::write(dir.join("summary.txt"), &table)?;
        std::fs::write(
            dir.join("sweep.json"),
            serde_json::to_string_pretty(&sweep)?,
        )?;
        eprintln!("wrote {}", dir.display());
    }
    check_oracle(&sweep.reports)?;
    if !sweep.failed.is_empty() {
        bail!(
            "{} file(s) or animation(s) failed: {}",
            sweep.failed.len(),
            sweep
                .failed
                .iter()
                .map(|f| f.source.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(())
}

#[cfg(test)]
mod generated_tests {
    use super::generated_sizes;

    #[test]
    fn generated_sizes_parse_counts_suffixes_and_none() {
        assert_eq!(generated_sizes("100k,1m").unwrap().0, [100_000, 1_000_000]);
        assert_eq!(generated_sizes(" 250000 ").unwrap().0, [250_000]);
        assert!(generated_sizes("none").unwrap().0.is_empty());
        for bad in ["", "k", "10", "5m", "1.5m", "-1k", "99999999999999999999m"] {
            assert!(generated_sizes(bad).is_err(), "{bad:?}");
        }
    }
}
