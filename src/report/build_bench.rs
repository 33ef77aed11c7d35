//! `build-bench`: every builder on one mesh: build time, SAH cost, size, trace speed, and
//! agreement with brute force.

use super::rays::RaySet;
use crate::bvh::{BuildParams, MeshBvh, brute_force_closest};
use crate::geom::{Hit, TriMesh};
use rayon::prelude::*;
use serde::Serialize;
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
    /// Sampled rays whose closest hit differs from brute force (ties at the same t aside).
    pub mismatches: usize,
    /// How many rays were compared with brute force.
    pub checked: usize,
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
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn time_ms(f: impl FnOnce()) -> f64 {
    let t = Instant::now();
    f();
    t.elapsed().as_secs_f64() * 1e3
}

/// Traces every ray in parallel (on the current rayon pool) and returns Mrays/s.
fn trace_mrays(rays: &RaySet, f: impl Fn(&crate::geom::Ray) -> bool + Sync) -> f64 {
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

/// Runs the whole comparison; `progress` is told each method as it starts.
pub fn run(
    mesh: &TriMesh,
    methods: &[BuildParams],
    sets: &[RaySet],
    opts: Options,
    mut progress: impl FnMut(&str),
) -> Vec<Row> {
    // Brute-force answers for a sample of each set, computed once for all methods.
    let samples: Vec<Vec<(usize, Option<Hit>)>> = sets
        .iter()
        .map(|s| {
            let step = (s.rays.len() / opts.check_rays.max(1)).max(1);
            (0..s.rays.len())
                .step_by(step)
                .take(opts.check_rays)
                .collect::<Vec<_>>()
                .into_par_iter()
                .map(|i| (i, brute_force_closest(mesh, &s.rays[i])))
                .collect()
        })
        .collect();

    let mut rows = Vec::new();
    for params in methods {
        let name = params.name();
        progress(&name);
        let mut bvh = None;
        let builds: Vec<f64> = (0..opts.build_runs.max(1))
            .map(|_| time_ms(|| bvh = Some(MeshBvh::build(mesh, params))))
            .collect();
        let mut bvh = bvh.expect("at least one build ran");
        let refits: Vec<f64> = (0..opts.build_runs.max(1))
            .map(|_| time_ms(|| bvh.refit(mesh)))
            .collect();
        let (build_ms, refit_ms) = (median(builds), median(refits));
        for (set, sample) in sets.iter().zip(&samples) {
            let closest = (0..opts.trace_runs.max(1))
                .map(|_| trace_mrays(set, |r| bvh.closest_hit(r).is_some()))
                .collect();
            let any = (0..opts.trace_runs.max(1))
                .map(|_| trace_mrays(set, |r| bvh.any_hit(r)))
                .collect();
            let mismatches = sample
                .iter()
                .filter(|(i, want)| !same_hit(*want, bvh.closest_hit(&set.rays[*i])))
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
                mismatches,
                checked: sample.len(),
            });
        }
    }
    rows
}

/// True when two closest-hit answers agree: both miss, or both hit at the same distance
/// (which triangle wins a tie at exactly the same distance may differ).
fn same_hit(a: Option<Hit>, b: Option<Hit>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => a.t == b.t,
        _ => false,
    }
}

/// Speed against quality: build time (x, log scale) against SAH cost (y), one point per
/// builder, so that every bin count and method can be read off as a trade-off.
#[must_use]
pub fn chart(rows: &[Row], title: &str) -> super::charts::Chart {
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
        x_label: "build time (ms, median)".into(),
        y_label: "SAH cost (Ct = Ci = 1)".into(),
        series,
        log_x: true,
        note: "lower left is better".into(),
        ..Default::default()
    }
}
