//! `dynbvh build-bench`: every builder on one mesh, as a table or JSON.

use super::args::{self, MemoryLimit};
use anyhow::{Context, Result, bail};
use clap::Args;
use dynbvh::accel::AccelKind;
use dynbvh::bvh::build::clip::MAX_POSES;
use dynbvh::bvh::optimize::OptimizeBudget;
use dynbvh::bvh::{BuildParams, Method};
use dynbvh::geom::{TriMesh, shapes};
use dynbvh::report::accel_bench;
use dynbvh::report::build_bench::{self, Builder, Options, Row};
use dynbvh::report::or_dash;
use dynbvh::report::rays::{RaySet, camera_rays, random_rays};
use dynbvh::report::rungs::Rung;
use dynbvh::report::wide_bench::{self, WideRow};
use std::path::{Path, PathBuf};

/// Rays per set by default (a square camera image of about as many rays, and as many random
/// rays), so that a default run on a small mesh takes seconds rather than minutes.
const DEFAULT_RAY_BUDGET: u64 = 1 << 15;

/// True when the triangle has finite vertices and a non-zero area (its edges' cross product
/// taken in f64, which neither overflows nor underflows for f32 coordinates).
fn has_area(t: &[glam::Vec3; 3]) -> bool {
    if !t.iter().all(|p| p.is_finite()) {
        return false;
    }
    let [a, b, c] = t.map(|p| p.as_dvec3());
    (b - a).cross(c - a) != glam::DVec3::ZERO
}

/// Triangle tests the brute-force check may spend per ray set.
const CHECK_WORK: usize = 1 << 28;

/// Arguments of `build-bench`.
#[derive(Args, Debug)]
pub struct BuildBenchArgs {
    /// Mesh: .glb/.gltf (default scene flattened at rest), .obj, or .tri.
    #[arg(required_unless_present = "synthetic", conflicts_with = "synthetic")]
    file: Option<PathBuf>,
    /// Use a bumpy geodesic sphere of about N triangles instead of a file.
    #[arg(long, allow_negative_numbers = true, value_name = "N", value_parser = clap::value_parser!(u64).range(1..=1 << 32))]
    synthetic: Option<u64>,
    /// Ray file(s) in the shared `.rays` format (repeatable); without any, a camera image and
    /// random rays of its own.
    #[arg(long = "ray-file", value_name = "FILE")]
    ray_files: Vec<PathBuf>,
    /// Most rays per ray set: the built-in camera is the largest square image within it, the
    /// random set this many rays, and a longer ray file is cut to its first N.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_RAY_BUDGET, value_parser = clap::value_parser!(u64).range(1..=1 << 32))]
    ray_budget: u64,
    /// Worker threads (default: all cores; more than the cores are capped).
    #[arg(long, allow_negative_numbers = true, value_parser = args::thread_count)]
    threads: Option<usize>,
    /// Builders, comma-separated: median, sweep, binnedK, binnedK-widest (default: all), each
    /// optionally followed by +opt (then optimised: three passes over a fifth of the interior
    /// nodes, or +optSHARE[xPASSES]), and
    /// the other structures: kdtree, kdtree-naive, bih, grid (gridL: L cells per triangle),
    /// grid2 (two levels), octree; and, for an animated glTF file, clip-aware[K] (a binned
    /// build over K poses of its first animation, default 4, the boxes of the file at rest).
    #[arg(long, value_delimiter = ',')]
    methods: Vec<String>,
    /// Builds per method; the median is reported.
    #[arg(long, allow_negative_numbers = true, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..=args::MAX_REPEATS))]
    runs: u64,
    /// Print the rows as JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Also write `build_bench.json` and the chart `build_bench.svg`/`.png` into this folder
    /// (and the wide trees' rows into `build_bench_wide.json`).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Skip the BVH4/BVH8 rows (wide trees collapsed from the binned16 tree). With `--json`
    /// they are only written to `--out`, so stdout stays one JSON array.
    #[arg(long)]
    no_wide: bool,
    #[command(flatten)]
    limits: MemoryLimit,
}

/// A builder, optionally followed by `+opt` or `+optSHARE[xPASSES]` (the build then
/// optimised; `+opt` is [`Builder::OPTIMIZE`]).
fn parse_method(s: &str) -> Result<Builder> {
    let Some((build, opt)) = s.split_once("+opt") else {
        return Ok(parse_build(s)?.into());
    };
    let optimize = if opt.is_empty() {
        Builder::OPTIMIZE
    } else {
        match format!("optimize:{opt}").parse::<Rung>() {
            Ok(Rung::Optimize { share, passes }) => OptimizeBudget {
                share,
                passes,
                ..Builder::OPTIMIZE
            },
            _ => bail!(
                "method {s:?}: after +opt, expected nothing or SHARE[xPASSES] (share in 0..=1, \
                 passes 1..=100)"
            ),
        }
    };
    Ok(Builder {
        params: parse_build(build)?,
        optimize: Some(optimize),
        clip: None,
    })
}

/// The `clip-aware[K]` method (`k` what follows the name): a binned build over `K` poses (4
/// when not given) of the file's first animation, evenly spaced over one loop from its start;
/// the tree's boxes are those of `mesh`, the file at rest.
fn clip_aware(file: Option<&Path>, mesh: &TriMesh, k: &str) -> Result<Builder> {
    let poses: usize = if k.is_empty() {
        4
    } else {
        k.parse()
            .ok()
            .filter(|p| (1..=MAX_POSES).contains(p))
            .with_context(|| {
                format!("method clip-aware{k}: the poses must be a count from 1 to {MAX_POSES}")
            })?
    };
    let path = file
        .filter(|p| {
            p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("glb") || e.eq_ignore_ascii_case("gltf"))
        })
        .context("method clip-aware needs an animated glTF file")?;
    let scene = super::load_scene(path, None)?;
    let anim = args::animation_or_first(&scene, path, None)?.with_context(|| {
        format!(
            "{}: no animation, so no clip for method clip-aware",
            path.display()
        )
    })?;
    let duration = scene.animations[anim].duration;
    let poses = (0..poses)
        .map(|i| {
            let m = scene.flatten_at(Some(anim), duration * i as f32 / poses as f32)?;
            if m.positions.len() != mesh.positions.len() {
                bail!(
                    "{}: a pose of {} vertices, the mesh at rest has {}",
                    path.display(),
                    m.positions.len(),
                    mesh.positions.len()
                );
            }
            Ok(m.positions)
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Builder {
        params: BuildParams::BINNED,
        optimize: None,
        clip: Some(poses.into()),
    })
}

fn parse_build(s: &str) -> Result<BuildParams> {
    Ok(match s {
        "median" => BuildParams::MEDIAN,
        "sweep" => BuildParams::SWEEP,
        _ => {
            let rest = s.strip_prefix("binned").with_context(|| {
                format!(
                    "unknown method {s:?}: median, sweep, binnedK, binnedK-widest (each with \
                     an optional +opt), kdtree, kdtree-naive, bih, grid, gridL, grid2, octree"
                )
            })?;
            let (k, widest) = match rest.strip_suffix("-widest") {
                Some(k) => (k, true),
                None => (rest, false),
            };
            let bins: usize = k
                .parse()
                .with_context(|| format!("bad bin count in {s:?}"))?;
            if !(2..=dynbvh::bvh::MAX_BINS).contains(&bins) {
                bail!(
                    "bin count {bins} out of range 2..={}",
                    dynbvh::bvh::MAX_BINS
                );
            }
            BuildParams {
                method: Method::Binned,
                all_axes: !widest,
                ..BuildParams::binned(bins)
            }
        }
    })
}

/// Loads a mesh by extension.
pub fn load_mesh(path: &Path, limit: &MemoryLimit) -> Result<TriMesh> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    Ok(match ext.as_str() {
        "tri" => dynbvh::io::read_tri(path)?,
        "obj" => dynbvh::io::read_obj(path)?,
        "glb" | "gltf" => crate::cli::flatten_gltf_at_rest(path, limit, args::BUILD_MEMORY)?,
        _ => bail!(
            "{}: unknown mesh format (expected .glb, .gltf, .obj or .tri)",
            path.display()
        ),
    })
}

/// Runs `build-bench`.
pub fn run(args: BuildBenchArgs) -> Result<()> {
    args::init_threads(args.threads)?;
    let (name, mesh) = match (&args.file, args.synthetic) {
        (Some(f), _) => (f.display().to_string(), load_mesh(f, &args.limits)?),
        (None, Some(n)) => {
            args.limits.check_memory(
                &format!("--synthetic {n} (the mesh and its trees)"),
                n.saturating_mul(args::BUILD_BYTES_PER_TRIANGLE),
            )?;
            (
                format!("synthetic sphere of about {n} triangles"),
                shapes::bumpy_sphere(n as usize),
            )
        }
        (None, None) => unreachable!("clap requires one"),
    };
    args.limits.check_memory(
        &format!("{name}: {} triangles (the mesh and its trees)", mesh.len()),
        (mesh.len() as u64).saturating_mul(args::BUILD_BYTES_PER_TRIANGLE),
    )?;
    mesh.check().map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    // A mesh of degenerate triangles only (a few bytes of glTF can ask for millions of
    // repeated zero indices) has nothing a ray can hit, and every tree over it is one point
    // that every ray through it must search whole.
    if !mesh.is_empty() && !(0..mesh.len()).any(|i| has_area(&mesh.triangle(i))) {
        bail!(
            "{name}: all {} triangles are degenerate (no area, or a vertex that is not finite): \
             no ray can hit them, nothing to benchmark",
            mesh.len()
        );
    }
    let (methods, structures) = if args.methods.is_empty() {
        (
            build_bench::default_methods()
                .into_iter()
                .map(Builder::from)
                .collect(),
            Vec::new(),
        )
    } else {
        let mut methods = Vec::new();
        let mut structures = Vec::new();
        for m in &args.methods {
            if let Some(k) = m.strip_prefix("clip-aware") {
                methods.push(clip_aware(args.file.as_deref(), &mesh, k)?);
                continue;
            }
            match m.parse::<AccelKind>() {
                Ok(k) => structures.push(k),
                Err(_) => methods.push(parse_method(m)?),
            }
        }
        (methods, structures)
    };
    let budget = args.ray_budget as usize;
    let sets = if args.ray_files.is_empty() {
        // The mesh's box less far outliers: what the camera and the random rays cover.
        let (b, _) = dynbvh::geom::framing_bounds(|f| {
            mesh.indices
                .iter()
                .flatten()
                .for_each(|&v| f(mesh.positions[v as usize]))
        });
        let side = (budget as f64).sqrt().floor().max(1.0) as usize;
        vec![
            RaySet {
                name: "camera".into(),
                rays: camera_rays(&b, side, side),
            },
            RaySet {
                name: "random".into(),
                rays: random_rays(&b, budget, 0xC0FFEE),
            },
        ]
    } else {
        args.ray_files
            .iter()
            .map(|p| {
                let mut rays = dynbvh::io::read_rays(p)?;
                rays.truncate(budget);
                Ok(RaySet {
                    name: p
                        .file_stem()
                        .map_or("rays".into(), |s| s.to_string_lossy().into_owned()),
                    rays,
                })
            })
            .collect::<Result<_>>()?
    };
    let threads = rayon::current_num_threads();
    eprintln!("{name}: {} triangles, {threads} thread(s)", mesh.len());
    // Brute force tests every triangle for every checked ray: on a huge mesh fewer rays are
    // checked (at least 16 per set), so that the check's triangle tests stay within
    // `CHECK_WORK` per set.
    let check_rays = (CHECK_WORK / mesh.len().max(1)).clamp(16, Options::default().check_rays);
    let opts = Options {
        build_runs: args.runs as usize,
        check_rays,
        ..Options::default()
    };
    let samples = build_bench::brute_force_samples(&mesh, &sets, opts.check_rays);
    let mut steps = super::progress::Steps::new(
        (methods.len() + structures.len()) as u64,
        "builders",
        "building and tracing",
    );
    let mut rows =
        build_bench::run_with_samples(&mesh, &methods, &sets, opts, &samples, |m| steps.start(m));
    rows.extend(accel_bench::run(
        &mesh,
        &structures,
        &sets,
        &samples,
        opts.build_runs,
        opts.trace_runs,
        |m| steps.start(m),
    ));
    steps.finish();
    let wide_rows = if args.no_wide {
        Vec::new()
    } else {
        let mut trees = super::progress::Steps::new(2, "wide trees", "collapsing and tracing");
        let rows = wide_bench::run(&mesh, &BuildParams::BINNED, &sets, opts, |t| {
            trees.start(&format!("{t} (collapsed from binned16)"));
        });
        trees.finish();
        rows
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        print_table(&rows);
        if !wide_rows.is_empty() {
            println!();
            print_wide_table(&wide_rows);
        }
    }
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let json = dir.join("build_bench.json");
        std::fs::write(&json, serde_json::to_string_pretty(&rows)?)
            .with_context(|| format!("writing {}", json.display()))?;
        let stem = dir.join("build_bench");
        let title = args
            .file
            .as_ref()
            .and_then(|f| f.file_name())
            .map_or_else(|| name.clone(), |f| f.to_string_lossy().into_owned());
        let with_sah: Vec<Row> = rows.iter().filter(|r| r.sah.is_finite()).cloned().collect();
        build_bench::chart(&with_sah, &title, args.runs as usize)
            .save(&stem, 900, 600)
            .with_context(|| format!("writing {}.svg/.png", stem.display()))?;
        eprintln!("wrote {} and {}.svg/.png", json.display(), stem.display());
        for set in &sets {
            let stem = dir.join(format!("build_bench_trace_{}", set.name));
            accel_bench::trace_chart(&rows, &set.name, &name)
                .save(&stem, 900, 600)
                .with_context(|| format!("writing {}.svg/.png", stem.display()))?;
            eprintln!("wrote {}.svg/.png", stem.display());
        }
        if !wide_rows.is_empty() {
            let json = dir.join("build_bench_wide.json");
            std::fs::write(&json, serde_json::to_string_pretty(&wide_rows)?)
                .with_context(|| format!("writing {}", json.display()))?;
            eprintln!("wrote {}", json.display());
        }
    }
    if rows.iter().any(|r| r.mismatches > 0) || wide_rows.iter().any(|r| r.mismatches > 0) {
        bail!("some rays disagree with brute force");
    }
    Ok(())
}

fn print_table(rows: &[Row]) {
    println!(
        "{:<16} {:>10} {:>9} {:>8} {:>9} {:>6} {:>9} {:<14} {:>8} {:>8} {:>8} {:>8} {:>9}",
        "method",
        "build ms",
        "refit ms",
        "SAH",
        "nodes",
        "depth",
        "MiB",
        "rays",
        "Mrays/s",
        "any Mr/s",
        "pkt Mr/s",
        "pkt any",
        "mismatch"
    );
    for r in rows {
        println!(
            "{:<16} {:>10.1} {:>9} {:>8} {:>9} {:>6} {:>9.1} {:<14} {:>8.2} {:>8.2} {:>8} {:>8} {:>5}/{:<3}",
            r.method,
            r.build_ms,
            or_dash(Some(r.refit_ms), 2),
            or_dash(Some(f64::from(r.sah)), 2),
            r.nodes,
            r.depth,
            r.memory_bytes as f64 / (1 << 20) as f64,
            r.rays,
            r.mrays,
            r.any_mrays,
            or_dash(Some(r.packet_mrays), 2),
            or_dash(Some(r.packet_any_mrays), 2),
            r.mismatches,
            r.checked
        );
    }
}

fn print_wide_table(rows: &[WideRow]) {
    println!(
        "{:<16} {:>11} {:>9} {:>8} {:>5} {:>6} {:>9} {:<14} {:>8} {:>8} {:>8} {:>8} {:>9}",
        "wide tree",
        "collapse ms",
        "refit ms",
        "nodes",
        "fill",
        "depth",
        "MiB",
        "rays",
        "Mrays/s",
        "any Mr/s",
        "pkt Mr/s",
        "pkt any",
        "mismatch"
    );
    for r in rows {
        println!(
            "{:<16} {:>11.1} {:>9.2} {:>8} {:>5.2} {:>6} {:>9.1} {:<14} {:>8.2} {:>8.2} {:>8.2} {:>8.2} {:>5}/{:<3}",
            format!("{} ({})", r.tree, r.from),
            r.collapse_ms,
            r.refit_ms,
            r.nodes,
            r.fill,
            r.depth,
            r.memory_bytes as f64 / (1 << 20) as f64,
            r.rays,
            r.mrays,
            r.any_mrays,
            r.packet_mrays,
            r.packet_any_mrays,
            r.mismatches,
            r.checked
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_builder_may_be_followed_by_an_optimisation() {
        let plain = parse_method("binned16").unwrap();
        assert_eq!(plain.optimize, None);
        assert_eq!(plain.name(), "binned16");
        let opt = parse_method("binned16+opt").unwrap();
        assert_eq!(opt.params, plain.params);
        assert_eq!(opt.optimize, Some(Builder::OPTIMIZE));
        assert_eq!(opt.name(), "binned16+opt");
        let b = parse_method("sweep+opt0.05x2").unwrap();
        assert_eq!(b.params, BuildParams::SWEEP);
        let budget = b.optimize.unwrap();
        assert_eq!((budget.share, budget.passes), (0.05, 2));
        assert_eq!(b.name(), "sweep+opt0.05x2");
        for bad in [
            "binned16+optx",
            "binned16+opt2",
            "binned16+opt0.1x0",
            "nope+opt",
        ] {
            let e = parse_method(bad).unwrap_err().to_string();
            assert!(e.contains(bad.split('+').next().unwrap()), "{bad}: {e}");
        }
    }
}
