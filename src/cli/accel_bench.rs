//! `dynbvh accel-bench`: what each acceleration structure costs per frame on an animation. The
//! BVH and the BIH are built at frame 0 and refitted on every later frame; the kd-tree, grid and
//! octree cannot be updated in place and are rebuilt. On every frame after the first each
//! structure is updated, then traces the frame's camera rays (single rays, closest hit, in this
//! thread) at each `--rays` count; its hits are compared on every ray with those of a refitted
//! BVH kept for reference, whose own hits are compared with brute force on a sample. Reported
//! per structure and ray count: median update and trace time per frame (CPU time where the
//! kernel gives it), their sum, and its ratio to the refitted BVH's, as a table, JSON and a
//! chart of the total against the rays per frame.

use super::args::{self, Limits};
use anyhow::{Context, Result, bail};
use clap::Args;
use dynbvh::accel::{Accel, AccelKind, Bih, BihParams};
use dynbvh::bvh::{BuildParams, BuildWorkspace, MeshBvh, brute_force_closest};
use dynbvh::cputime::{CpuClock, thread_times_ns};
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::geom::{Hit, Ray, TriMesh};
use dynbvh::report::charts::{Chart, Series};
use dynbvh::report::rays::camera_rays;
use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

/// Bytes a ray of a frame's sets costs: the ray, the reference's hit and the traced hit.
const RAY_BYTES: u64 = 128;

/// Most rays per frame in one set.
const MAX_RAYS: u64 = 1 << 24;

/// Triangle tests the brute-force check of the reference may spend per frame and ray set.
const CHECK_WORK: u64 = 1 << 24;

/// Arguments of `accel-bench`.
#[derive(Args, Debug)]
pub struct AccelBenchArgs {
    /// Animated glTF file (.glb/.gltf); all its instances flattened into one mesh per frame.
    file: PathBuf,
    /// Animation name or index (default: the first).
    #[arg(long, short)]
    animation: Option<String>,
    /// Frames spread over one loop of the animation: the structures are built at frame 0 (the
    /// animation's start) and updated and traced on frames 1 to N.
    #[arg(long, allow_negative_numbers = true, default_value_t = 30,
          value_parser = clap::value_parser!(u64).range(1..=args::MAX_TIMELINE))]
    frames: u64,
    /// Structures, comma separated: bvh (binned SAH, refitted), bvh-rebuild, bih (refitted),
    /// bih-rebuild, kdtree, kdtree-naive, grid, gridL (L cells per triangle), grid2 (two
    /// levels), octree (the last five rebuilt every frame).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "bvh,bih,kdtree,grid,grid2,octree"
    )]
    structures: Vec<Structure>,
    /// Rays per frame, comma separated, each traced every frame (k = 1024, m = 2^20): camera
    /// rays of a square-ish image looking at frame 0's mesh.
    #[arg(long, value_delimiter = ',', default_value = "1k,64k", value_parser = ray_count)]
    rays: Vec<u64>,
    /// Rays per frame and ray set on which the reference BVH is checked against brute force.
    #[arg(long, allow_negative_numbers = true, default_value_t = 64,
          value_parser = clap::value_parser!(u64).range(0..=1 << 20))]
    check: u64,
    /// Worker threads of the builds (the traces run in one thread).
    #[arg(long, allow_negative_numbers = true, default_value = "1", value_parser = args::thread_count)]
    threads: usize,
    /// Print the report as JSON instead of the table.
    #[arg(long)]
    json: bool,
    /// Also write `accel_bench.json` and the chart `accel_bench.svg`/`.png` into this folder.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    #[command(flatten)]
    limits: Limits,
}

/// Parses a ray count: a whole number, or one with a `k` (1024) or `m` (2^20) suffix.
fn ray_count(s: &str) -> std::result::Result<u64, String> {
    let t = s.trim().to_ascii_lowercase();
    let (digits, unit) = match t.strip_suffix('k') {
        Some(d) => (d, 1u64 << 10),
        None => match t.strip_suffix('m') {
            Some(d) => (d, 1 << 20),
            None => (t.as_str(), 1),
        },
    };
    let n = digits
        .parse::<u64>()
        .ok()
        .and_then(|n| n.checked_mul(unit))
        .ok_or_else(|| format!("{s:?} is not a ray count (e.g. 1000, 1k, 64k, 1m)"))?;
    if !(1..=MAX_RAYS).contains(&n) {
        return Err(format!("{s:?}: rays per frame must be 1 to {MAX_RAYS}"));
    }
    Ok(n)
}

/// A structure and how it follows the animation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Structure {
    /// The binary BVH (binned SAH, 16 bins): refitted (`bvh`) or rebuilt (`bvh-rebuild`), its
    /// storage and build workspace reused.
    Bvh { rebuild: bool },
    /// The BIH, refitted (`bih`).
    BihRefit,
    /// Built anew every frame (`bih-rebuild` is the BIH).
    Rebuilt(AccelKind),
}

impl Structure {
    /// True when the structure is rebuilt every frame.
    fn rebuilds(self) -> bool {
        !matches!(
            self,
            Structure::Bvh { rebuild: false } | Structure::BihRefit
        )
    }
}

impl fmt::Display for Structure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Structure::Bvh { rebuild: false } => f.write_str("bvh"),
            Structure::Bvh { rebuild: true } => f.write_str("bvh-rebuild"),
            Structure::BihRefit => f.write_str("bih"),
            Structure::Rebuilt(AccelKind::Bih) => f.write_str("bih-rebuild"),
            Structure::Rebuilt(k) => k.fmt(f),
        }
    }
}

impl FromStr for Structure {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Ok(match s.trim() {
            "bvh" => Structure::Bvh { rebuild: false },
            "bvh-rebuild" => Structure::Bvh { rebuild: true },
            "bih" => Structure::BihRefit,
            "bih-rebuild" => Structure::Rebuilt(AccelKind::Bih),
            other => Structure::Rebuilt(other.parse::<AccelKind>().map_err(|_| {
                format!(
                    "unknown structure {other:?}: bvh, bvh-rebuild, bih, bih-rebuild, kdtree, \
                     kdtree-naive, grid, gridL (L cells per triangle), grid2, octree"
                )
            })?),
        })
    }
}

/// A structure as the frames update it.
enum Live {
    Bvh {
        tree: MeshBvh,
        ws: BuildWorkspace,
        rebuild: bool,
    },
    Bih(Bih),
    Rebuilt {
        kind: AccelKind,
        tree: Box<dyn Accel>,
    },
}

impl Live {
    fn build(s: Structure, mesh: &TriMesh) -> Self {
        match s {
            Structure::Bvh { rebuild } => {
                let mut tree = MeshBvh::default();
                let mut ws = BuildWorkspace::default();
                tree.rebuild_indexed(
                    &mesh.positions,
                    &mesh.indices,
                    &BuildParams::BINNED,
                    &mut ws,
                );
                Live::Bvh { tree, ws, rebuild }
            }
            Structure::BihRefit => Live::Bih(Bih::build(mesh, &BihParams::default())),
            Structure::Rebuilt(kind) => Live::Rebuilt {
                kind,
                tree: kind.build(mesh),
            },
        }
    }

    /// Follows the mesh to its new positions (the same triangles): a refit, or a rebuild (the
    /// old structure's release counted with it).
    fn update(&mut self, mesh: &TriMesh) {
        match self {
            Live::Bvh {
                tree,
                ws,
                rebuild: true,
            } => tree.rebuild_indexed(&mesh.positions, &mesh.indices, &BuildParams::BINNED, ws),
            Live::Bvh { tree, .. } => tree.refit(mesh),
            Live::Bih(b) => b.refit_to(mesh),
            Live::Rebuilt { kind, tree } => *tree = kind.build(mesh),
        }
    }

    fn accel(&self) -> &dyn Accel {
        match self {
            Live::Bvh { tree, .. } => tree,
            Live::Bih(b) => b,
            Live::Rebuilt { tree, .. } => tree.as_ref(),
        }
    }
}

/// One structure's measurements over the frames.
struct Track {
    structure: Structure,
    live: Live,
    build_ms: f64,
    /// Per frame: update time, measured and wall clock.
    update: Vec<f64>,
    update_wall: Vec<f64>,
    /// Per ray set, per frame: trace time, measured and wall clock.
    trace: Vec<Vec<f64>>,
    trace_wall: Vec<Vec<f64>>,
    /// Per ray set: rays whose closest hit differs from the reference's, over all frames.
    mismatches: Vec<usize>,
}

/// One structure at one ray count.
#[derive(serde::Serialize, Clone, Debug)]
struct Row {
    method: String,
    /// `refit` or `rebuild`.
    update: &'static str,
    rays_per_frame: usize,
    /// Frames updated and traced (frame 0, the build, not counted).
    frames: usize,
    /// The build at frame 0.
    build_ms: f64,
    /// Median update per frame.
    update_ms: f64,
    /// Median trace of the frame's rays.
    trace_ms: f64,
    /// `update_ms + trace_ms`.
    total_ms: f64,
    /// `total_ms` over the refitted BVH's at the same ray count (none without a `bvh` row).
    ratio_to_bvh: Option<f64>,
    /// The same medians in wall-clock time.
    update_wall_ms: f64,
    trace_wall_ms: f64,
    /// Bytes held after the last frame.
    memory_bytes: usize,
    /// Rays (over all frames) whose closest hit is not the reference BVH's.
    mismatches: usize,
    /// Rays compared.
    checked: usize,
}

/// The whole run.
#[derive(serde::Serialize, Debug)]
struct Report {
    file: String,
    animation: Option<String>,
    triangles: usize,
    frames: usize,
    threads: usize,
    /// What `update_ms` and `trace_ms` measure: `on-core` (the wall clock less the time the
    /// threads waited for a core), or `wall` where the kernel does not count the waits.
    clock: &'static str,
    /// Median of an empty measured interval (included in every figure).
    clock_overhead_ms: f64,
    /// Rays on which the reference BVH was compared with brute force, and how many differed.
    reference_checked: usize,
    reference_mismatches: usize,
    rows: Vec<Row>,
}

/// The measure's name in the table and chart.
fn clock_name(on_core: bool) -> &'static str {
    if on_core {
        "on-core (wall clock less waits for a core)"
    } else {
        "wall-clock"
    }
}

fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let m = s.len() / 2;
    if s.len() % 2 == 1 {
        s[m]
    } else {
        0.5 * (s[m - 1] + s[m])
    }
}

/// The closest hits of `rays` through `s`, into `hits`, in this thread.
fn trace(s: &dyn Accel, rays: &[Ray], hits: &mut [Option<Hit>]) {
    for (h, r) in hits.iter_mut().zip(rays) {
        *h = s.closest_hit(r);
    }
}

/// Hits agree when both miss or both are at the same distance (a tie may name either
/// triangle).
fn same_hit(a: Option<Hit>, b: Option<Hit>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => a.t == b.t,
        _ => false,
    }
}

/// Runs `f`, returning (measured ms, wall ms). Measured is the wall clock less the time this
/// process's threads were runnable but waited for a core (when the kernel counts it): with one
/// thread working at a time, its time on a core. The kernel's per-thread CPU time itself is
/// only brought up to date at scheduler ticks on some kernels, too coarse for a frame's update,
/// while the wait is added exactly whenever a thread gets a core back.
fn timed(f: impl FnOnce()) -> (f64, f64) {
    let c = CpuClock::now();
    f();
    let e = c.elapsed_ms();
    ((e.wall_ms - e.wait_ms).max(0.0), e.wall_ms)
}

/// `n` camera rays looking at `bounds`: the rows of an image `ceil(sqrt n)` wide, the last row
/// cut short.
fn frame_rays(bounds: &dynbvh::geom::Aabb, n: usize) -> Vec<Ray> {
    let w = (n as f64).sqrt().ceil().max(1.0) as usize;
    let mut r = camera_rays(bounds, w, n.div_ceil(w));
    r.truncate(n);
    r
}

/// Sets up the global pool of the builds: `threads` workers (capped at the cores), this thread
/// the first of them, so that with one thread all the work runs here: no other thread is
/// runnable at the same time, and the waits subtracted are this thread's alone.
fn init_pool(threads: usize) -> Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
    if threads > cores {
        eprintln!("warning: --threads {threads}: this machine has {cores} cores; using {cores}");
    }
    let t = threads.min(cores);
    rayon::ThreadPoolBuilder::new()
        .num_threads(t)
        .use_current_thread()
        .build_global()
        .map_err(|e| anyhow::anyhow!("setting up the thread pool of {t} threads: {e}"))
}

/// Runs `accel-bench`.
pub fn run(a: AccelBenchArgs) -> Result<()> {
    init_pool(a.threads)?;
    let file = a.file.display().to_string();
    a.limits
        .check_frames(&format!("--frames {}", a.frames), a.frames as f64)?;
    let total_rays = a.rays.iter().sum::<u64>();
    a.limits.check_memory(
        &format!("--rays {total_rays} in all per frame"),
        total_rays.saturating_mul(RAY_BYTES),
    )?;
    let scene = super::load_scene(&a.file, None)?;
    // Every structure, the reference BVH and the flattened mesh live at once.
    a.limits
        .memory
        .check_scene(&scene, args::BUILD_MEMORY, a.structures.len() as u64 + 1)?;
    let anim = args::animation_or_first(&scene, &a.file, a.animation.as_deref())?;
    if anim.is_none() {
        eprintln!("{file}: no animation; every frame is the rest pose");
    }
    let times = GltfSource::new(&scene, anim, FrameTimes::Count(a.frames as usize))?
        .times()
        .to_vec();
    let mut poser = scene.poser(anim)?;
    let mut mesh = TriMesh::default();
    poser.pose(times[0]);
    poser.flatten_into(&mut mesh);
    mesh.check().map_err(|e| anyhow::anyhow!("{file}: {e}"))?;
    if mesh.is_empty() {
        bail!("{file}: the scene has no triangles: nothing to trace");
    }

    // The camera looks at frame 0's mesh (less far outliers) for the whole run.
    let (bounds, _) = dynbvh::geom::framing_bounds(|f| {
        mesh.indices
            .iter()
            .flatten()
            .for_each(|&v| f(mesh.positions[v as usize]));
    });
    let sets: Vec<Vec<Ray>> = a
        .rays
        .iter()
        .map(|&n| frame_rays(&bounds, n as usize))
        .collect();
    let longest = sets.iter().map(Vec::len).max().unwrap_or(0);
    let mut ref_hits: Vec<Vec<Option<Hit>>> = sets.iter().map(|s| vec![None; s.len()]).collect();
    let mut hits: Vec<Option<Hit>> = vec![None; longest];
    let check = (CHECK_WORK / mesh.len() as u64).clamp(1, a.check.max(1)) as usize;
    let check = if a.check == 0 { 0 } else { check };

    let cpu = thread_times_ns().is_some();
    let overhead: Vec<f64> = (0..31).map(|_| timed(|| {}).0).collect();
    let clock_overhead_ms = median(&overhead);
    let frames = a.frames as usize;
    eprintln!(
        "{file}: {} triangles, {frames} frames after frame 0, rays per frame {}, {} thread(s), \
         {}",
        mesh.len(),
        a.rays
            .iter()
            .map(u64::to_string)
            .collect::<Vec<_>>()
            .join(", "),
        rayon::current_num_threads(),
        clock_name(cpu)
    );

    let mut reference = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let mut tracks: Vec<Track> = a
        .structures
        .iter()
        .map(|&s| {
            let mut live = None;
            let (build_ms, _) = timed(|| live = Some(Live::build(s, &mesh)));
            Track {
                structure: s,
                live: live.expect("the build ran"),
                build_ms,
                update: Vec::with_capacity(frames),
                update_wall: Vec::with_capacity(frames),
                trace: sets.iter().map(|_| Vec::with_capacity(frames)).collect(),
                trace_wall: sets.iter().map(|_| Vec::with_capacity(frames)).collect(),
                mismatches: vec![0; sets.len()],
            }
        })
        .collect();
    let (mut reference_checked, mut reference_mismatches) = (0usize, 0usize);
    let bar = super::progress::bar(frames as u64, "frames", "updating and tracing");
    for &t in &times[1..] {
        poser.pose(t);
        poser.flatten_into(&mut mesh);
        reference.refit(&mesh);
        for (rays, want) in sets.iter().zip(&mut ref_hits) {
            trace(&reference, rays, want);
            for k in 0..check.min(rays.len()) {
                let i = k * rays.len() / check.min(rays.len());
                reference_checked += 1;
                if !same_hit(want[i], brute_force_closest(&mesh, &rays[i])) {
                    reference_mismatches += 1;
                }
            }
        }
        for tr in &mut tracks {
            let (u, uw) = timed(|| tr.live.update(&mesh));
            tr.update.push(u);
            tr.update_wall.push(uw);
            for (k, (rays, want)) in sets.iter().zip(&ref_hits).enumerate() {
                let got = &mut hits[..rays.len()];
                let (m, mw) = timed(|| trace(tr.live.accel(), rays, got));
                tr.trace[k].push(m);
                tr.trace_wall[k].push(mw);
                tr.mismatches[k] += got
                    .iter()
                    .zip(want)
                    .filter(|&(&g, &w)| !same_hit(g, w))
                    .count();
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    for tr in &tracks {
        tr.live
            .accel()
            .validate(&mesh)
            .map_err(|e| anyhow::anyhow!("{file}: {} after the last frame: {e}", tr.structure))?;
    }

    let rows = rows(&tracks, &sets, frames);
    let report = Report {
        file: file.clone(),
        animation: anim.map(|k| {
            scene.animations[k]
                .name
                .clone()
                .unwrap_or_else(|| k.to_string())
        }),
        triangles: mesh.len(),
        frames,
        threads: rayon::current_num_threads(),
        clock: if cpu { "on-core" } else { "wall" },
        clock_overhead_ms,
        reference_checked,
        reference_mismatches,
        rows,
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_table(&report);
    }
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let json = dir.join("accel_bench.json");
        std::fs::write(&json, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", json.display()))?;
        let stem = dir.join("accel_bench");
        let title = a
            .file
            .file_name()
            .map_or_else(|| file.clone(), |f| f.to_string_lossy().into_owned());
        chart(&report, &title)
            .save(&stem, 900, 600)
            .with_context(|| format!("writing {}.svg/.png", stem.display()))?;
        eprintln!("wrote {} and {}.svg/.png", json.display(), stem.display());
    }
    if report.reference_mismatches > 0 {
        bail!(
            "{file}: the reference BVH disagrees with brute force on {} of {} rays",
            report.reference_mismatches,
            report.reference_checked
        );
    }
    if report.rows.iter().any(|r| r.mismatches > 0) {
        bail!("{file}: some structures' closest hits differ from the BVH's (column mismatch)");
    }
    Ok(())
}

/// The rows, ray count by ray count, the structures in the order asked.
fn rows(tracks: &[Track], sets: &[Vec<Ray>], frames: usize) -> Vec<Row> {
    let mut rows = Vec::new();
    for (k, rays) in sets.iter().enumerate() {
        let start = rows.len();
        for tr in tracks {
            let update_ms = median(&tr.update);
            let trace_ms = median(&tr.trace[k]);
            rows.push(Row {
                method: tr.structure.to_string(),
                update: if tr.structure.rebuilds() {
                    "rebuild"
                } else {
                    "refit"
                },
                rays_per_frame: rays.len(),
                frames,
                build_ms: tr.build_ms,
                update_ms,
                trace_ms,
                total_ms: update_ms + trace_ms,
                ratio_to_bvh: None,
                update_wall_ms: median(&tr.update_wall),
                trace_wall_ms: median(&tr.trace_wall[k]),
                memory_bytes: tr.live.accel().memory_bytes(),
                mismatches: tr.mismatches[k],
                checked: rays.len() * frames,
            });
        }
        let bvh = rows[start..]
            .iter()
            .find(|r| r.method == "bvh")
            .map(|r| r.total_ms);
        for r in &mut rows[start..] {
            r.ratio_to_bvh = bvh.filter(|&b| b > 0.0).map(|b| r.total_ms / b);
        }
    }
    rows
}

fn print_table(r: &Report) {
    println!(
        "{}: {} triangles, {} frames after frame 0, {} thread(s); medians per frame, ms of {} \
         (an empty measurement reads {:.4} ms)",
        r.file,
        r.triangles,
        r.frames,
        r.threads,
        clock_name(r.clock != "wall"),
        r.clock_overhead_ms
    );
    println!(
        "{:<14} {:<8} {:>10} {:>10} {:>10} {:>10} {:>10} {:>8} {:>12}",
        "structure",
        "update",
        "rays",
        "build ms",
        "update ms",
        "trace ms",
        "total ms",
        "× bvh",
        "mismatch"
    );
    for row in &r.rows {
        println!(
            "{:<14} {:<8} {:>10} {:>10.2} {:>10.3} {:>10.3} {:>10.3} {:>8} {:>12}",
            row.method,
            row.update,
            row.rays_per_frame,
            row.build_ms,
            row.update_ms,
            row.trace_ms,
            row.total_ms,
            row.ratio_to_bvh
                .map_or_else(|| "–".to_string(), |x| format!("{x:.2}")),
            format!("{}/{}", row.mismatches, row.checked)
        );
    }
    println!(
        "reference BVH against brute force: {} of {} sampled rays differ",
        r.reference_mismatches, r.reference_checked
    );
}

/// Total per frame (update + trace, y, log scale) against rays per frame (x, log scale), one
/// line per structure: where the lines cross, the cheaper structure changes.
fn chart(r: &Report, title: &str) -> Chart {
    let mut series: Vec<Series> = Vec::new();
    for row in r.rows.iter().filter(|row| row.total_ms > 0.0) {
        let name = if row.method.ends_with("-rebuild") {
            row.method.clone()
        } else {
            format!("{} ({})", row.method, row.update)
        };
        let point = (row.rays_per_frame as f64, row.total_ms);
        match series.iter_mut().find(|s| s.name == name) {
            Some(s) => s.points.push(point),
            None => series.push(Series {
                name,
                points: vec![point],
                line: true,
                ..Default::default()
            }),
        }
    }
    Chart {
        title: format!("cost per frame, update + trace: {title}"),
        x_label: "rays per frame".into(),
        y_label: "update + trace, ms per frame (median)".into(),
        series,
        log_x: true,
        log_y: true,
        note: format!(
            "{} frames, {} triangles, {} thread(s), single-ray closest hits; ms {}; lower is \
             better",
            r.frames,
            r.triangles,
            r.threads,
            clock_name(r.clock != "wall")
        ),
        ..Default::default()
    }
}
