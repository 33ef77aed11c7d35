//! `build-bench`: every builder on one mesh: build time, SAH cost, size, trace speed, and
//! agreement with brute force.

use super::rays::RaySet;
use crate::bvh::optimize::{OptimizeBudget, OptimizeScratch};
use crate::bvh::topology::RestructureWorkspace;
use crate::bvh::{BuildParams, MeshBvh, TILE_H, brute_force_closest};
use crate::geom::{Hit, TriMesh};
use glam::Vec3;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

/// One row of the report: one builder on one ray set.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// Builder name (`median`, `binned16`, `sweep`, ...).
    pub method: String,
    /// Median build time over the runs, milliseconds.
    pub build_ms: f64,
    /// Median refit time of the built tree (same vertices), milliseconds.
    pub refit_ms: f64,
    /// SAH cost, both constants 1, normalised by the root's area.
    pub sah: f32,
    /// Node count.
    pub nodes: usize,
    /// Depth of the deepest leaf.
    pub depth: usize,
    /// Bytes of nodes, indices and leaf-ordered triangles.
    pub memory_bytes: usize,
    /// Name of the ray set.
    pub rays: String,
    /// Number of rays in the set.
    pub ray_count: usize,
    /// Closest-hit rays per second, millions (median over the trace runs).
    pub mrays: f64,
    /// Any-hit rays per second, millions.
    pub any_mrays: f64,
    /// Closest-hit rays per second traced as packets (16x8 tiles of a square camera image,
    /// else runs of 128 consecutive rays, each traced ray by ray unless coherent), millions.
    pub packet_mrays: f64,
    /// Any-hit rays per second traced as packets, millions.
    pub packet_any_mrays: f64,
    /// Sampled rays whose closest hit differs from brute force (ties at the same t aside).
    pub mismatches: usize,
    /// How many rays were compared with brute force.
    pub checked: usize,
}

/// One builder of the comparison: a build, optionally followed by insertion-based
/// optimisation ([`MeshBvh::optimize`]), its time counted in the build's; or, with `clip`, a
/// clip-aware build ([`MeshBvh::build_clip_aware`]) over those poses of the mesh's vertices,
/// with the mesh's own positions for its boxes.
#[derive(Clone, Debug, PartialEq)]
pub struct Builder {
    pub params: BuildParams,
    pub optimize: Option<OptimizeBudget>,
    pub clip: Option<Arc<[Vec<Vec3>]>>,
}

impl Builder {
    /// The build's name, with `+opt` (and the budget when it is not [`Builder::OPTIMIZE`]).
    #[must_use]
    pub fn name(&self) -> String {
        let build = match &self.clip {
            Some(poses) => format!("clip-aware{}", poses.len()),
            None => self.params.name(),
        };
        match self.optimize {
            None => build,
            Some(b) if b == Self::OPTIMIZE => format!("{build}+opt"),
            Some(b) => format!("{build}+opt{}x{}", b.share, b.passes),
        }
    }

    /// The optimisation `+opt` means: three passes over a fifth of the interior nodes.
    pub const OPTIMIZE: OptimizeBudget = OptimizeBudget {
        share: 0.2,
        passes: 3,
        max_visits: 4096,
    };

    /// Builds (and optimises) a tree over `mesh`.
    #[must_use]
    pub fn build(&self, mesh: &TriMesh) -> MeshBvh {
        let mut bvh = match &self.clip {
            Some(poses) => {
                let poses: Vec<&[Vec3]> = poses.iter().map(Vec::as_slice).collect();
                MeshBvh::build_clip_aware(&mesh.positions, &mesh.indices, &poses, &self.params)
            }
            None => MeshBvh::build(mesh, &self.params),
        };
        if let Some(budget) = self.optimize {
            bvh.optimize(
                budget,
                &mut RestructureWorkspace::default(),
                &mut OptimizeScratch::default(),
            );
        }
        bvh
    }
}

impl From<BuildParams> for Builder {
    fn from(params: BuildParams) -> Self {
        Self {
            params,
            optimize: None,
            clip: None,
        }
    }
}

/// How much to measure.
#[derive(Clone, Copy, Debug)]
pub struct Options {
    /// Builds per method (the median is reported).
    pub build_runs: usize,
    /// Passes over each ray set (the median is reported).
    pub trace_runs: usize,
    /// Rays per set compared with brute force.
    pub check_rays: usize,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            build_runs: 5,
            trace_runs: 3,
            check_rays: 256,
        }
    }
}

/// The builders `build-bench` compares by default: the median baseline, binned SAH with 4 to
/// 32 bins on all axes and 16 bins on the widest axis only, and the full sweep.
#[must_use]
pub fn default_methods() -> Vec<BuildParams> {
    let mut v = vec![BuildParams::MEDIAN];
    v.extend([4, 8, 16, 32].map(BuildParams::binned));
    v.push(BuildParams {
        all_axes: false,
        ..BuildParams::BINNED
    });
    v.push(BuildParams::SWEEP);
    v
}

/// Median of a non-empty list.
pub(super) fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Wall-clock milliseconds `f` takes.
pub(super) fn time_ms(f: impl FnOnce()) -> f64 {
    let t = Instant::now();
    f();
    t.elapsed().as_secs_f64() * 1e3
}

/// Traces every ray in parallel (on the current rayon pool) and returns Mrays/s.
pub(super) fn trace_mrays(rays: &RaySet, f: impl Fn(&crate::geom::Ray) -> bool + Sync) -> f64 {
    let hits = std::sync::atomic::AtomicUsize::new(0);
    let ms = time_ms(|| {
        let n = rays
            .rays
            .par_chunks(4096)
            .map(|c| c.iter().filter(|r| f(r)).count())
            .sum::<usize>();
        hits.store(n, std::sync::atomic::Ordering::Relaxed);
    });
    rays.rays.len() as f64 / (ms * 1e3)
}

/// Side of the square image a ray set is, if it is one (camera sets are rows of pixels).
fn image_side(rays: &[crate::geom::Ray]) -> Option<usize> {
    let side = (rays.len() as f64).sqrt().round() as usize;
    (side * side == rays.len() && side > 0).then_some(side)
}

/// Answers for the whole set through a tree's packet queries, in parallel bands: a square image
/// in bands of [`TILE_H`] rows through `image` (which tiles them), else runs of 4096
/// consecutive rays through `run` (packets of consecutive rays).
pub(super) fn trace_in_packets<T: Copy + Default + Send>(
    rays: &[crate::geom::Ray],
    image: impl Fn(&[crate::geom::Ray], usize, &mut [T]) + Sync,
    run: impl Fn(&[crate::geom::Ray], &mut [T]) + Sync,
) -> Vec<T> {
    let mut out = vec![T::default(); rays.len()];
    match image_side(rays) {
        Some(w) => out
            .par_chunks_mut(TILE_H * w)
            .zip(rays.par_chunks(TILE_H * w))
            .for_each(|(o, r)| image(r, w, o)),
        None => out
            .par_chunks_mut(4096)
            .zip(rays.par_chunks(4096))
            .for_each(|(o, r)| run(r, o)),
    }
    out
}

/// Closest hits of the whole set through the binary tree's packets.
fn packet_closest(set: &RaySet, bvh: &MeshBvh) -> Vec<Option<Hit>> {
    trace_in_packets(
        &set.rays,
        |r, w, h| bvh.trace_image_closest(r, w, h),
        |r, h| bvh.closest_hit_packet(r, h),
    )
}

/// Any-hit answers of the whole set through the binary tree's packets.
fn packet_any(set: &RaySet, bvh: &MeshBvh) -> Vec<bool> {
    trace_in_packets(
        &set.rays,
        |r, w, o| bvh.trace_image_any(r, w, o),
        |r, o| bvh.any_hit_packet(r, o),
    )
}

/// Traces the set as packets in parallel and returns Mrays/s; `any`: any hit, else closest.
fn packet_mrays(set: &RaySet, bvh: &MeshBvh, any: bool) -> f64 {
    let ms = time_ms(|| {
        if any {
            std::hint::black_box(packet_any(set, bvh));
        } else {
            std::hint::black_box(packet_closest(set, bvh));
        }
    });
    set.rays.len() as f64 / (ms * 1e3)
}

/// Brute force's closest hits for a sample of one ray set: `(ray index, hit)`.
pub type Samples = Vec<(usize, Option<Hit>)>;

/// Brute-force answers for `check_rays` rays evenly spread through each set, computed once for
/// all methods.
#[must_use]
pub fn brute_force_samples(mesh: &TriMesh, sets: &[RaySet], check_rays: usize) -> Vec<Samples> {
    sets.iter()
        .map(|s| {
            let step = (s.rays.len() / check_rays.max(1)).max(1);
            (0..s.rays.len())
                .step_by(step)
                .take(check_rays)
                .collect::<Vec<_>>()
                .into_par_iter()
                .map(|i| (i, brute_force_closest(mesh, &s.rays[i])))
                .collect()
        })
        .collect()
}

/// Runs the whole comparison; `progress` is told each method as it starts.
pub fn run(
    mesh: &TriMesh,
    methods: &[Builder],
    sets: &[RaySet],
    opts: Options,
    progress: impl FnMut(&str),
) -> Vec<Row> {
    let samples = brute_force_samples(mesh, sets, opts.check_rays);
    run_with_samples(mesh, methods, sets, opts, &samples, progress)
}

/// [`run`] with brute force's answers already computed ([`brute_force_samples`]).
pub fn run_with_samples(
    mesh: &TriMesh,
    methods: &[Builder],
    sets: &[RaySet],
    opts: Options,
    samples: &[Samples],
    mut progress: impl FnMut(&str),
) -> Vec<Row> {
    let mut rows = Vec::new();
    for builder in methods {
        let name = builder.name();
        progress(&name);
        let mut bvh = None;
        let builds: Vec<f64> = (0..opts.build_runs.max(1))
            .map(|_| time_ms(|| bvh = Some(builder.build(mesh))))
            .collect();
        let mut bvh = bvh.expect("at least one build ran");
        let refits: Vec<f64> = (0..opts.build_runs.max(1))
            .map(|_| time_ms(|| bvh.refit(mesh)))
            .collect();
        let (build_ms, refit_ms) = (median(builds), median(refits));
        for (set, sample) in sets.iter().zip(samples) {
            let closest = (0..opts.trace_runs.max(1))
                .map(|_| trace_mrays(set, |r| bvh.closest_hit(r).is_some()))
                .collect();
            let any = (0..opts.trace_runs.max(1))
                .map(|_| trace_mrays(set, |r| bvh.any_hit(r)))
                .collect();
            let packet = (0..opts.trace_runs.max(1))
                .map(|_| packet_mrays(set, &bvh, false))
                .collect();
            let packet_any_runs = (0..opts.trace_runs.max(1))
                .map(|_| packet_mrays(set, &bvh, true))
                .collect();
            let packet_hits = packet_closest(set, &bvh);
            let packet_occluded = packet_any(set, &bvh);
            let mismatches = sample
                .iter()
                .filter(|(i, want)| {
                    !same_hit(*want, bvh.closest_hit(&set.rays[*i]))
                        || !same_hit(*want, packet_hits[*i])
                        || packet_occluded[*i] != want.is_some()
                })
                .count();
            rows.push(Row {
                method: name.clone(),
                build_ms,
                refit_ms,
                sah: bvh.bvh().sah_cost(),
                nodes: bvh.bvh().nodes().len(),
                depth: bvh.bvh().depth(),
                memory_bytes: bvh.memory_bytes(),
                rays: set.name.clone(),
                ray_count: set.rays.len(),
                mrays: median(closest),
                any_mrays: median(any),
                packet_mrays: median(packet),
                packet_any_mrays: median(packet_any_runs),
                mismatches,
                checked: sample.len(),
            });
        }
    }
    rows
}

/// True when two closest-hit answers agree: both miss, or both hit at the same distance
/// (which triangle wins a tie at exactly the same distance may differ).
pub(super) fn same_hit(a: Option<Hit>, b: Option<Hit>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => a.t == b.t,
        _ => false,
    }
}

/// Speed against quality: build time (x, log scale) against SAH cost (y), one point per
/// builder, so that every bin count and method can be read off as a trade-off.
#[must_use]
pub fn chart(rows: &[Row], title: &str, runs: usize) -> super::charts::Chart {
    let mut series: Vec<super::charts::Series> = Vec::new();
    for r in rows {
        if series.iter().any(|s| s.name == r.method) {
            continue;
        }
        series.push(super::charts::Series {
            name: r.method.clone(),
            points: vec![(r.build_ms, f64::from(r.sah))],
            ..Default::default()
        });
    }
    super::charts::Chart {
        title: format!("build time against SAH cost: {title}"),
        x_label: format!(
            "build time (ms, {})",
            if runs > 1 {
                format!("median of {runs} runs")
            } else {
                "one run".into()
            }
        ),
        y_label: "SAH cost (traversal = intersection = 1)".into(),
        series,
        log_x: true,
        min_rel_span: 0.1,
        note: "one marker per builder;  lower left is better".into(),
        ..Default::default()
    }
}
