//! `dynbvh bench`: every refit-or-rebuild policy on the same frames and rays of an animation.

use anyhow::{Context, Result, bail};
use clap::Args;
use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::{FrameSource, SineSphere};
use dynbvh::engine::{CostMeasure, Policy, Prices, Traversal};
use dynbvh::report::frame_bench::{self, Options, RaySpec, Sweep, SweepFailure};
use std::path::{Path, PathBuf};

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
    /// Instead of a file: a bumpy sphere of about N triangles deformed by a travelling wave.
    #[arg(long, value_name = "N")]
    synthetic: Option<usize>,
    /// Animation name or index (default: the first).
    #[arg(long, short)]
    animation: Option<String>,
    /// Frames spread over one loop of the animation (default 60).
    #[arg(long, conflicts_with = "fps")]
    frames: Option<usize>,
    /// Frames per second of animation time instead of a frame count.
    #[arg(long)]
    fps: Option<f32>,
    /// Rays per frame, from a camera looking at the first frame.
    #[arg(long, conflicts_with = "size")]
    rays: Option<usize>,
    /// Camera image size WxH (default 256x256).
    #[arg(long, value_name = "WxH")]
    size: Option<String>,
    /// Cast the `--rays` (default 65536) of a spinning lidar-like fan above the scene instead of
    /// camera rays; they turn from frame to frame.
    #[arg(long, conflicts_with = "size")]
    lidar: bool,
    /// Policy to run (repeatable): refit, rebuild, periodic:N, threshold:R, amortized,
    /// amortized-plain.
    /// Default: all of refit, rebuild, periodic:8, threshold:1.3, amortized, amortized-plain.
    #[arg(long = "policy", short)]
    policies: Vec<String>,
    /// Directory for frames.csv, report.json and the charts (SVG and PNG).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the report as JSON instead of the table.
    #[arg(long)]
    json: bool,
    /// Skip the oracle (it builds at every frame and refits through the later ones) and the
    /// always-refit and always-rebuild runs it needs (unless asked for with `--policy`).
    #[arg(long)]
    no_oracle: bool,
    /// Skip the builder points of the speed-against-accuracy chart (each rebuilds every frame
    /// with one builder, the full sweep included: slow on large meshes).
    #[arg(long)]
    no_builders: bool,
    /// Skip the top-level tree comparison (the default mesh policy run again under each
    /// top-level tree policy).
    #[arg(long)]
    no_tlas_compare: bool,
    /// Trace passes per frame, the fastest counting.
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Mesh trees the rays walk: binary, or wide (8-wide trees kept beside the binary ones).
    #[arg(long, value_name = "binary|wide", default_value_t = Traversal::DEFAULT)]
    traversal: Traversal,
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

fn parse_size(s: &str) -> Result<(usize, usize)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .with_context(|| format!("size {s:?}: expected WxH"))?;
    let (w, h): (usize, usize) = (w.trim().parse()?, h.trim().parse()?);
    if w == 0 || h == 0 {
        bail!("size {s:?}: both sides must be positive");
    }
    Ok((w, h))
}

/// Runs `bench`.
pub fn run(a: BenchArgs) -> Result<()> {
    if let Some(t) = a.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build_global()
            .context("setting up the thread pool")?;
    }
    let mut opts = Options {
        trace_repeats: a.repeats.max(1),
        oracle: !a.no_oracle,
        tlas_compare: !a.no_tlas_compare,
        traversal: a.traversal,
        cost: a.cost,
        prices: prices(&a)?,
        ..Options::default()
    };
    if a.no_builders {
        opts.builders.clear();
    }
    if !a.policies.is_empty() {
        opts.policies = a
            .policies
            .iter()
            .map(|p| p.parse::<Policy>().map_err(anyhow::Error::from))
            .collect::<Result<_>>()?;
    }
    opts.rays = match (a.rays, &a.size) {
        (n, _) if a.lidar => RaySpec::Lidar(n.unwrap_or(65_536).max(1)),
        (Some(n), _) => RaySpec::Count(n.max(1)),
        (None, Some(s)) => {
            let (w, h) = parse_size(s)?;
            RaySpec::Size(w, h)
        }
        (None, None) => RaySpec::Size(256, 256),
    };
    let times = match (a.frames, a.fps) {
        (_, Some(fps)) if fps > 0.0 && fps.is_finite() => FrameTimes::Fps(fps),
        (_, Some(fps)) => bail!("--fps {fps}: must be positive"),
        (Some(n), None) => FrameTimes::Count(n.max(1)),
        (None, None) => FrameTimes::Count(60),
    };
    let progress = |m: &str| eprintln!("  {m} ...");
    if a.all {
        if a.rays.is_none() && a.size.is_none() {
            opts.rays = RaySpec::Size(128, 128);
        }
        let times = match (a.frames, a.fps) {
            (None, None) => FrameTimes::Count(30),
            _ => times,
        };
        opts.builders.clear();
        return sweep(&a, &opts, times);
    }
    let report = match (&a.file, a.synthetic) {
        (Some(path), _) => {
            let scene = super::load_scene(path, None)?;
            let anim = match &a.animation {
                Some(k) => Some(
                    scene
                        .find_animation(k)
                        .with_context(|| format!("{}: no animation {k:?}", path.display()))?,
                ),
                None if scene.animations.is_empty() => {
                    eprintln!(
                        "{}: no animation; every frame is the rest pose",
                        path.display()
                    );
                    None
                }
                None => Some(0),
            };
            let mut src = GltfSource::new(&scene, anim, times)?;
            eprintln!("{}: {} frames", src.name(), src.frames());
            frame_bench::run(&mut src, &opts, progress)
        }
        (None, Some(n)) => {
            let frames = match times {
                FrameTimes::Count(n) => n,
                FrameTimes::Fps(f) => f.ceil() as usize,
            };
            let mut src = SineSphere::new(n, frames, 0.02, 0.15);
            eprintln!("{}: {} frames", src.name(), src.frames());
            frame_bench::run(&mut src, &opts, progress)
        }
        (None, None) => unreachable!("clap requires one"),
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", frame_bench::summary_table(&report));
    }

    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        std::fs::write(
            dir.join("frames.csv"),
            frame_bench::to_csv(&report.per_frame),
        )?;
        std::fs::write(
            dir.join("report.json"),
            serde_json::to_string_pretty(&report)?,
        )?;
        for (stem, chart) in frame_bench::charts(&report) {
            chart
                .save(&dir.join(stem), 960, 540)
                .with_context(|| format!("writing chart {stem}"))?;
        }
        eprintln!("wrote {}", dir.display());
    }
    check_oracle(std::slice::from_ref(&report))
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
            let mut src = match GltfSource::new(&scene, Some(anim), times) {
                Ok(s) => s,
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
        std::fs::write(dir.join("sweep.txt"), &table)?;
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
