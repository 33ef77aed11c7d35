//! The wide-tree rows of `build-bench`: BVH4 and BVH8 collapsed from one binary tree, with
//! collapse time, refit time, size, trace speed and agreement with brute force.

use super::build_bench::{Options, trace_in_packets};
use super::rays::RaySet;
use crate::bvh::{BuildParams, MeshBvh, WideBvh, brute_force_closest};
use crate::geom::{Hit, Ray, TriMesh};
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

/// One row: one wide tree on one ray set.
#[derive(Clone, Debug, Serialize)]
pub struct WideRow {
    /// `bvh4` or `bvh8`.
    pub tree: String,
    /// The binary builder the tree was collapsed from.
    pub from: String,
    /// Median time to collapse the binary tree (triangle copies included), milliseconds.
    pub collapse_ms: f64,
    /// Median refit time of the wide tree itself (same vertices), milliseconds.
    pub refit_ms: f64,
    /// Wide nodes.
    pub nodes: usize,
    /// Average children per node.
    pub fill: f64,
    /// Depth of the deepest node.
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
    /// Closest-hit rays per second traced as packets over the wide tree (16x8 tiles of a
    /// square camera image, else runs of 128 consecutive rays, each traced ray by ray unless
    /// coherent), millions.
    pub packet_mrays: f64,
    /// Any-hit rays per second traced as packets over the wide tree, millions.
    pub packet_any_mrays: f64,
    /// Sampled rays whose closest hit (single ray or packet) differs from brute force (ties at
    /// the same t aside), or whose any hit differs from the closest hit's existence.
    pub mismatches: usize,
    /// How many rays were compared with brute force.
    pub checked: usize,
}

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
fn trace_mrays(rays: &[Ray], f: impl Fn(&Ray) -> bool + Sync) -> f64 {
    let ms = time_ms(|| {
        let n = rays
            .par_chunks(4096)
            .map(|c| c.iter().filter(|r| f(r)).count())
            .sum::<usize>();
        std::hint::black_box(n);
    });
    rays.len() as f64 / (ms * 1e3)
}

/// Closest hits of the whole set through the wide tree's packets.
fn packet_closest<const K: usize>(rays: &[Ray], w: &WideBvh<K>) -> Vec<Option<Hit>> {
    trace_in_packets(
        rays,
        |r, side, h| w.trace_image_closest(r, side, h),
        |r, h| w.closest_hit_packet(r, h),
    )
}

/// Any-hit answers of the whole set through the wide tree's packets.
fn packet_any<const K: usize>(rays: &[Ray], w: &WideBvh<K>) -> Vec<bool> {
    trace_in_packets(
        rays,
        |r, side, o| w.trace_image_any(r, side, o),
        |r, o| w.any_hit_packet(r, o),
    )
}

/// Builds the binary tree with `params`, collapses it into BVH4 and BVH8, and measures both on
/// every ray set; `progress` is told each tree as it starts.
pub fn run(
    mesh: &TriMesh,
    params: &BuildParams,
    sets: &[RaySet],
    opts: Options,
    mut progress: impl FnMut(&str),
) -> Vec<WideRow> {
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
    let bin = MeshBvh::build(mesh, params);
    let mut rows = Vec::new();
    rows.extend(measure::<4>(
        mesh,
        &bin,
        params,
        sets,
        &samples,
        opts,
        &mut progress,
    ));
    rows.extend(measure::<8>(
        mesh,
        &bin,
        params,
        sets,
        &samples,
        opts,
        &mut progress,
    ));
    rows
}

fn measure<const K: usize>(
    mesh: &TriMesh,
    bin: &MeshBvh,
    params: &BuildParams,
    sets: &[RaySet],
    samples: &[Vec<(usize, Option<Hit>)>],
    opts: Options,
    progress: &mut impl FnMut(&str),
) -> Vec<WideRow> {
    let tree = format!("bvh{K}");
    progress(&tree);
    let runs = opts.build_runs.max(1);
    let mut w = None;
    let collapse = (0..runs)
        .map(|_| time_ms(|| w = Some(WideBvh::<K>::from_mesh_bvh(bin))))
        .collect();
    let mut w = w.expect("at least one collapse ran");
    let refit = (0..runs).map(|_| time_ms(|| w.refit(mesh))).collect();
    let (collapse_ms, refit_ms) = (median(collapse), median(refit));
    let mut rows = Vec::new();
    for (set, sample) in sets.iter().zip(samples) {
        let runs = opts.trace_runs.max(1);
        let closest = (0..runs)
            .map(|_| trace_mrays(&set.rays, |r| w.closest_hit(r).is_some()))
            .collect();
        let any = (0..runs)
            .map(|_| trace_mrays(&set.rays, |r| w.any_hit(r)))
            .collect();
        let n = set.rays.len() as f64;
        let packet = (0..runs)
            .map(|_| {
                let ms = time_ms(|| {
                    std::hint::black_box(packet_closest(&set.rays, &w));
                });
                n / (ms * 1e3)
            })
            .collect();
        let packet_any_runs = (0..runs)
            .map(|_| {
                let ms = time_ms(|| {
                    std::hint::black_box(packet_any(&set.rays, &w));
                });
                n / (ms * 1e3)
            })
            .collect();
        let packet_hits = packet_closest(&set.rays, &w);
        let packet_occluded = packet_any(&set.rays, &w);
        let mismatches = sample
            .iter()
            .filter(|(i, want)| {
                let r = &set.rays[*i];
                let got = w.closest_hit(r);
                let want_t = want.map(|h| h.t);
                got.map(|h| h.t) != want_t
                    || packet_hits[*i].map(|h| h.t) != want_t
                    || w.any_hit(r) != want.is_some()
                    || packet_occluded[*i] != want.is_some()
            })
            .count();
        rows.push(WideRow {
            tree: tree.clone(),
            from: params.name(),
            collapse_ms,
            refit_ms,
            nodes: w.nodes().len(),
            fill: w.fill(),
            depth: w.depth(),
            memory_bytes: w.memory_bytes(),
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
    rows
}
