//! `build-bench --methods kdtree,kdtree-naive,bih,grid,grid2,octree`: the course's other structures
//! measured as the BVH builders are (build time, size, single-ray closest and any hit, agreement
//! with brute force), in the same rows, and their build time against trace time per ray.

use super::build_bench::{Row, Samples, median, same_hit, time_ms, trace_mrays};
use super::charts::{Chart, Series};
use super::rays::RaySet;
use crate::accel::{Accel, AccelKind};
use crate::geom::TriMesh;

/// Measures each structure of `kinds` on `mesh` and `sets` (`samples`: brute force's answers
/// for a sample of each set, from [`super::build_bench::brute_force_samples`]); `progress` is
/// told each structure as it starts. Rows hold NaN where a figure is not defined (packets, and
/// SAH and refit for the structures without them).
pub fn run(
    mesh: &TriMesh,
    kinds: &[AccelKind],
    sets: &[RaySet],
    samples: &[Samples],
    build_runs: usize,
    trace_runs: usize,
    mut progress: impl FnMut(&str),
) -> Vec<Row> {
    let mut rows = Vec::new();
    for kind in kinds {
        let name = kind.to_string();
        progress(&name);
        let mut built: Option<Box<dyn Accel>> = None;
        let builds: Vec<f64> = (0..build_runs.max(1))
            .map(|_| {
                drop(built.take());
                time_ms(|| built = Some(kind.build(mesh)))
            })
            .collect();
        let mut s = built.expect("at least one build ran");
        let refit_ms = if kind.refits() {
            median(
                (0..build_runs.max(1))
                    .map(|_| time_ms(|| assert!(s.refit(mesh))))
                    .collect(),
            )
        } else {
            f64::NAN
        };
        let build_ms = median(builds);
        for (set, sample) in sets.iter().zip(samples) {
            let closest = (0..trace_runs.max(1))
                .map(|_| trace_mrays(set, |r| s.closest_hit(r).is_some()))
                .collect();
            let any = (0..trace_runs.max(1))
                .map(|_| trace_mrays(set, |r| s.any_hit(r)))
                .collect();
            let mismatches = sample
                .iter()
                .filter(|(i, want)| {
                    let r = &set.rays[*i];
                    !same_hit(*want, s.closest_hit(r)) || s.any_hit(r) != want.is_some()
                })
                .count();
            rows.push(Row {
                method: name.clone(),
                build_ms,
                refit_ms,
                sah: s.sah().unwrap_or(f32::NAN),
                nodes: s.nodes(),
                depth: s.depth(),
                memory_bytes: s.memory_bytes(),
                rays: set.name.clone(),
                ray_count: set.rays.len(),
                mrays: median(closest),
                any_mrays: median(any),
                packet_mrays: f64::NAN,
                packet_any_mrays: f64::NAN,
                mismatches,
                checked: sample.len(),
            });
        }
    }
    rows
}

/// Build time (x, log scale) against closest-hit trace time per ray (y, log scale) on one ray
/// set, one point per structure and builder.
#[must_use]
pub fn trace_chart(rows: &[Row], rays: &str, title: &str) -> Chart {
    let series = rows
        .iter()
        .filter(|r| r.rays == rays && r.mrays > 0.0)
        .map(|r| Series {
            name: r.method.clone(),
            points: vec![(r.build_ms, 1e3 / r.mrays)],
            ..Default::default()
        })
        .collect();
    Chart {
        title: format!("build time against trace time per ray ({rays} rays): {title}"),
        x_label: "build time (ms, median)".into(),
        y_label: "closest hit, ns per ray (median)".into(),
        series,
        log_x: true,
        log_y: true,
        note: "lower left is better".into(),
        ..Default::default()
    }
}
