//! The clip-aware tree against the plain one on the largest deforming mesh of an animation:
//! both built at frame 0 and refitted through the clip, each frame's SAH and ray work over a
//! tree freshly built at that frame ([`MeshBvh::build_clip_aware`]).

use crate::bvh::{BuildParams, MeshBvh};
use crate::cputime::CpuClock;
use crate::engine::source::FrameSource;
use crate::geom::{Aabb, Ray};
use glam::Vec3;
use std::fmt::Write as _;

/// Options of a run.
#[derive(Clone, Debug)]
pub struct Options {
    /// Poses the clip-aware tree is built from, evenly spread over the frames (frame 0 first).
    pub poses: usize,
    /// Camera rays (width, height) aimed at the mesh in each frame, for the ray work.
    pub rays: (usize, usize),
}

/// One tree's figures over the clip: refitted tree over the frame's fresh tree.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TreeRow {
    pub tree: String,
    /// Build at frame 0, ms (wall; and the process CPU time).
    pub build_ms: f64,
    pub build_cpu_ms: f64,
    /// SAH over the fresh tree's: mean and worst over the frames.
    pub mean_sah_ratio: f64,
    pub max_sah_ratio: f64,
    /// The clip's summed SAH over the fresh trees' summed SAH (the objective's ratio).
    pub clip_sah_ratio: f64,
    /// Ray work (nodes + triangles of the camera rays, binary tree) over the fresh tree's, the
    /// clip's sums.
    pub clip_work_ratio: f64,
}

/// The run's result.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Report {
    pub name: String,
    pub triangles: usize,
    pub frames: usize,
    pub poses: usize,
    pub threads: usize,
    /// Median fresh build over the frames, ms.
    pub fresh_build_ms: f64,
    pub rows: Vec<TreeRow>,
    /// Per frame: SAH ratio of the plain and the clip-aware tree.
    pub per_frame: Vec<[f64; 2]>,
}

fn work(tree: &MeshBvh, rays: &[Ray]) -> f64 {
    crate::report::rays::closest_hit_work(rays, |r, w| {
        let _ = tree.closest_hit_counted(r, w);
    })
}

/// Runs the comparison on the largest deforming mesh of `src`, over all its frames.
///
/// # Errors
/// When the source has no deforming mesh or fewer than two frames.
pub fn run(src: &mut dyn FrameSource, opts: &Options) -> anyhow::Result<Report> {
    let frames = src.frames();
    anyhow::ensure!(frames >= 2, "{}: fewer than two frames", src.name());
    let (mut e, mesh) = super::refit_engine_on_largest_mesh(src)?;
    let indices = e.indices(mesh).to_vec();
    let mut positions: Vec<Vec<Vec3>> = vec![e.positions(mesh).to_vec()];
    for f in 1..frames {
        src.advance(&mut e, f);
        e.update();
        positions.push(e.positions(mesh).to_vec());
    }
    let params = BuildParams::BINNED;
    let k = opts.poses.clamp(1, frames);
    let poses: Vec<&[Vec3]> = (0..k)
        .map(|i| {
            let f = if k == 1 {
                0
            } else {
                i * (frames - 1) / (k - 1)
            };
            positions[f].as_slice()
        })
        .collect();
    let timed = |build: &dyn Fn() -> MeshBvh| {
        let clock = CpuClock::now();
        let t = std::time::Instant::now();
        let tree = build();
        let ms = t.elapsed().as_secs_f64() * 1e3;
        (tree, ms, clock.elapsed_ms().cpu_ms)
    };
    let (plain, plain_ms, plain_cpu) =
        timed(&|| MeshBvh::build_indexed(&positions[0], &indices, &params));
    let (clip, clip_ms, clip_cpu) =
        timed(&|| MeshBvh::build_clip_aware(&positions[0], &indices, &poses, &params));
    let mut trees = [plain, clip];
    let mut sums = [[0.0f64; 2]; 2];
    let (mut fresh_sah, mut fresh_work) = (0.0f64, 0.0f64);
    let mut per_frame = Vec::with_capacity(frames);
    let mut fresh_ms = Vec::with_capacity(frames);
    let mut max = [0.0f64; 2];
    for pos in &positions {
        let rays =
            crate::report::rays::camera_rays(&Aabb::from_points(pos), opts.rays.0, opts.rays.1);
        let t = std::time::Instant::now();
        let fresh = MeshBvh::build_indexed(pos, &indices, &params);
        fresh_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let (fs, fw) = (f64::from(fresh.bvh().sah_cost()), work(&fresh, &rays));
        fresh_sah += fs;
        fresh_work += fw;
        let mut row = [0.0; 2];
        for (i, tree) in trees.iter_mut().enumerate() {
            tree.refit_indexed(pos, &indices);
            let s = f64::from(tree.bvh().sah_cost());
            sums[i][0] += s;
            sums[i][1] += work(tree, &rays);
            row[i] = if fs > 0.0 { s / fs } else { 1.0 };
            max[i] = max[i].max(row[i]);
        }
        per_frame.push(row);
    }
    fresh_ms.sort_by(f64::total_cmp);
    let n = per_frame.len() as f64;
    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { 1.0 };
    let rows = [
        ("binned16 at frame 0", plain_ms, plain_cpu),
        ("clip-aware", clip_ms, clip_cpu),
    ]
    .iter()
    .enumerate()
    .map(|(i, &(name, ms, cpu))| TreeRow {
        tree: name.into(),
        build_ms: ms,
        build_cpu_ms: cpu,
        mean_sah_ratio: per_frame.iter().map(|r| r[i]).sum::<f64>() / n,
        max_sah_ratio: max[i],
        clip_sah_ratio: ratio(sums[i][0], fresh_sah),
        clip_work_ratio: ratio(sums[i][1], fresh_work),
    })
    .collect();
    Ok(Report {
        name: src.name(),
        triangles: indices.len(),
        frames,
        poses: k,
        threads: rayon::current_num_threads(),
        fresh_build_ms: fresh_ms[fresh_ms.len() / 2],
        rows,
        per_frame,
    })
}

/// The report as a text table.
#[must_use]
pub fn table(r: &Report) -> String {
    let mut s = format!(
        "{}: {} triangles, {} frames, clip-aware from {} poses, {} threads; fresh build {:.2} ms \
         (median)\n{:<22} {:>9} {:>9} {:>10} {:>9} {:>10} {:>11}\n",
        r.name,
        r.triangles,
        r.frames,
        r.poses,
        r.threads,
        r.fresh_build_ms,
        "tree (refitted)",
        "build ms",
        "cpu ms",
        "SAH mean",
        "SAH max",
        "SAH clip",
        "work clip"
    );
    for row in &r.rows {
        let _ = writeln!(
            s,
            "{:<22} {:>9.2} {:>9.2} {:>10.3} {:>9.3} {:>10.3} {:>11.3}",
            row.tree,
            row.build_ms,
            row.build_cpu_ms,
            row.mean_sah_ratio,
            row.max_sah_ratio,
            row.clip_sah_ratio,
            row.clip_work_ratio
        );
    }
    s.push_str("(ratios: the refitted tree over a tree freshly built at each frame)\n");
    s
}
