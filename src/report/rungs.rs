//! The rungs between refit and rebuild, side by side on one deforming mesh: a tree refitted
//! from the first frame on, and on sampled frames a copy of it optimised, partly rebuilt or
//! rebuilt. Each rung's time (wall-clock median and CPU time, binary tree and with the 8-wide
//! collapse) and what it recovered of the quality refitting lost: of the SAH, and of the ray
//! work (nodes visited plus triangles tested by camera rays on the 8-wide tree).

use crate::bvh::optimize::{OptimizeBudget, OptimizeScratch};
use crate::bvh::partial::{PartialCut, PartialScratch};
use crate::bvh::topology::RestructureWorkspace;
use crate::bvh::{BuildParams, BuildWorkspace, MeshBvh, MeshBvh8};
use crate::cputime::CpuClock;
use crate::engine::source::FrameSource;
use crate::geom::Ray;
use std::fmt::Write as _;
use std::time::Instant;

/// Share of a fresh tree's cost a frame's refitted tree must have lost for the frame to say how
/// much of the loss a rung wins back (below it, the recovered share is mostly rounding).
pub const MIN_LOSS: f64 = 0.01;

/// One rung.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub enum Rung {
    /// Insertion-based optimisation of this share of the interior nodes, this many passes.
    Optimize { share: f32, passes: u32 },
    /// Partial rebuild of at most this share of the triangles (and the top).
    Partial { share: f32 },
    /// Full rebuild.
    Rebuild,
}

impl std::fmt::Display for Rung {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Rung::Optimize { share, passes } => write!(f, "optimize:{share}x{passes}"),
            Rung::Partial { share } => write!(f, "partial:{share}"),
            Rung::Rebuild => f.write_str("rebuild"),
        }
    }
}

impl std::str::FromStr for Rung {
    type Err = String;

    /// `optimize:SHARE` or `optimize:SHARExPASSES`, `partial:SHARE`, `rebuild` (shares in
    /// 0 ..= 1).
    fn from_str(s: &str) -> Result<Self, String> {
        let share = |v: &str| -> Result<f32, String> {
            match v.trim().parse::<f32>() {
                Ok(x) if (0.0..=1.0).contains(&x) => Ok(x),
                _ => Err(format!("rung {s:?}: the share must be a number in 0..=1")),
            }
        };
        match s.trim().split_once(':') {
            None if s.trim() == "rebuild" => Ok(Rung::Rebuild),
            Some(("partial", v)) => Ok(Rung::Partial { share: share(v)? }),
            Some(("optimize", v)) => {
                let (v, passes) = match v.split_once('x') {
                    Some((v, p)) => match p.trim().parse::<u32>() {
                        Ok(p) if (1..=100).contains(&p) => (v, p),
                        _ => return Err(format!("rung {s:?}: passes must be 1..=100")),
                    },
                    None => (v, 1),
                };
                Ok(Rung::Optimize {
                    share: share(v)?,
                    passes,
                })
            }
            _ => Err(format!(
                "rung {s:?}: expected optimize:SHARE[xPASSES], partial:SHARE or rebuild"
            )),
        }
    }
}

/// Options of a run.
#[derive(Clone, Debug)]
pub struct Options {
    pub rungs: Vec<Rung>,
    /// Measure every `step`-th frame.
    pub step: usize,
    /// Timed repeats of each rung per measured frame (the median is kept).
    pub repeats: usize,
    /// Camera rays (width, height) aimed at the mesh.
    pub rays: (usize, usize),
}

impl Default for Options {
    fn default() -> Self {
        Self {
            rungs: vec![
                Rung::Optimize {
                    share: 0.01,
                    passes: 1,
                },
                Rung::Optimize {
                    share: 0.05,
                    passes: 1,
                },
                Rung::Partial { share: 0.1 },
                Rung::Partial { share: 0.25 },
                Rung::Rebuild,
            ],
            step: 5,
            repeats: 3,
            rays: (128, 128),
        }
    }
}

/// One rung's figures, medians over the measured frames.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RungRow {
    pub rung: String,
    /// Binary tree operation, ms (wall median, CPU mean).
    pub wall_ms: f64,
    pub cpu_ms: f64,
    /// With the 8-wide collapse after it.
    pub wall_with_collapse_ms: f64,
    /// Share of the SAH (and ray work) refitting lost that the rung won back (1: as a fresh
    /// build; negative: worse than the refitted tree); NaN (`null` in JSON) when no measured
    /// frame had lost more than [`MIN_LOSS`] of the fresh tree's cost.
    pub sah_recovered: f64,
    pub work_recovered: f64,
    /// Wall time over a full rebuild's in the same frames (binary; with collapse).
    pub time_ratio: f64,
    pub time_ratio_with_collapse: f64,
}

/// The run's result.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Report {
    pub name: String,
    pub triangles: usize,
    pub frames: Vec<usize>,
    pub threads: usize,
    pub rows: Vec<RungRow>,
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn median_or_nan(v: Vec<f64>) -> f64 {
    if v.is_empty() { f64::NAN } else { median(v) }
}

fn pct(x: f64) -> String {
    if x.is_finite() {
        format!("{:.0}%", 100.0 * x)
    } else {
        super::NOT_COMPUTED.into()
    }
}

fn work(tree: &MeshBvh8, rays: &[Ray]) -> f64 {
    crate::report::rays::closest_hit_work(rays, |r, w| {
        let _ = tree.closest_hit_counted(r, w);
    })
}

/// Runs `opts.rungs` on the largest deforming mesh of `src`.
///
/// # Errors
/// When the source has no deforming mesh.
pub fn run(src: &mut dyn FrameSource, opts: &Options) -> anyhow::Result<Report> {
    let (mut e, mesh) = super::refit_engine_on_largest_mesh(src)?;
    let params = BuildParams::BINNED;
    let indices = e.indices(mesh).to_vec();
    let mut refitted = MeshBvh::build_indexed(e.positions(mesh), &indices, &params);
    let mut cut = PartialCut::default();
    let mut ps = PartialScratch::default();
    cut.reset(&refitted, &mut ps);
    // The rungs work on a tree and scratch with the room the engine gives a deforming mesh's
    // (any shape of tree over its triangles), so that they trade buffers as they do there.
    let mut ws = RestructureWorkspace::default();
    ws.reserve(indices.len());
    let mut t = refitted.clone();
    t.reserve_any_shape();
    let mut os = OptimizeScratch::default();
    let mut bws = BuildWorkspace::default();
    let mut wide = MeshBvh8::from_mesh_bvh(&refitted);
    let n = opts.rungs.len();
    let (mut wall, mut cpu, mut wall_c) = (vec![vec![]; n], vec![0.0; n], vec![vec![]; n]);
    let (mut sah_rec, mut work_rec) = (vec![vec![]; n], vec![vec![]; n]);
    let mut frames = Vec::new();
    let mut rebuild_wall = Vec::new();
    let mut rebuild_wall_c = Vec::new();
    for f in 1..src.frames() {
        src.advance(&mut e, f);
        e.update();
        let pos = e.positions(mesh).to_vec();
        refitted.refit_indexed(&pos, &indices);
        if f % opts.step.max(1) != 0 {
            continue;
        }
        frames.push(f);
        let (b, _) = crate::geom::framing_bounds(|f| {
            indices.iter().flatten().for_each(|&v| f(pos[v as usize]))
        });
        let rays = crate::report::rays::camera_rays(&b, opts.rays.0, opts.rays.1);
        wide.collapse_from(&refitted);
        let (refit_sah, refit_work) = (f64::from(refitted.bvh().sah_cost()), work(&wide, &rays));
        let fresh = MeshBvh::build_indexed(&pos, &indices, &params);
        wide.collapse_from(&fresh);
        let (fresh_sah, fresh_work) = (f64::from(fresh.bvh().sah_cost()), work(&wide, &rays));
        let mut frame_rebuild = (0.0, 0.0);
        for (k, rung) in opts.rungs.iter().enumerate() {
            let mut walls = Vec::new();
            let mut walls_c = Vec::new();
            let mut result = refitted.clone();
            for _ in 0..opts.repeats.max(1) {
                // Into the same storage each time, as the engine's tree is.
                t.clone_from(&refitted);
                let mut c = cut.clone();
                let clock = CpuClock::now();
                let start = Instant::now();
                match *rung {
                    Rung::Optimize { share, passes } => {
                        let budget = OptimizeBudget {
                            share,
                            passes,
                            ..OptimizeBudget::default()
                        };
                        t.optimize(budget, &mut ws, &mut os);
                    }
                    Rung::Partial { share } => {
                        t.partial_rebuild(&mut c, share, &params, &mut ws, &mut ps);
                    }
                    Rung::Rebuild => t.rebuild_indexed(&pos, &indices, &params, &mut bws),
                }
                let ms = start.elapsed().as_secs_f64() * 1e3;
                wide.collapse_from(&t);
                let ms_c = start.elapsed().as_secs_f64() * 1e3;
                cpu[k] += clock.elapsed_ms().cpu_ms / opts.repeats.max(1) as f64;
                walls.push(ms);
                walls_c.push(ms_c);
                result.clone_from(&t);
            }
            wide.collapse_from(&result);
            let (s, w) = (f64::from(result.bvh().sah_cost()), work(&wide, &rays));
            let lost_sah = refit_sah - fresh_sah;
            let lost_work = refit_work - fresh_work;
            if lost_sah > MIN_LOSS * fresh_sah {
                sah_rec[k].push((refit_sah - s) / lost_sah);
            }
            if lost_work > MIN_LOSS * fresh_work {
                work_rec[k].push((refit_work - w) / lost_work);
            }
            let (mw, mwc) = (median(walls), median(walls_c));
            if *rung == Rung::Rebuild {
                frame_rebuild = (mw, mwc);
            }
            wall[k].push(mw);
            wall_c[k].push(mwc);
        }
        rebuild_wall.push(frame_rebuild.0);
        rebuild_wall_c.push(frame_rebuild.1);
    }
    let (rb, rbc) = (median(rebuild_wall), median(rebuild_wall_c));
    let m = frames.len().max(1) as f64;
    let rows = opts
        .rungs
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let w = median(wall[k].clone());
            let wc = median(wall_c[k].clone());
            RungRow {
                rung: r.to_string(),
                wall_ms: w,
                cpu_ms: cpu[k] / m,
                wall_with_collapse_ms: wc,
                sah_recovered: median_or_nan(sah_rec[k].clone()),
                work_recovered: median_or_nan(work_rec[k].clone()),
                time_ratio: if rb > 0.0 { w / rb } else { 0.0 },
                time_ratio_with_collapse: if rbc > 0.0 { wc / rbc } else { 0.0 },
            }
        })
        .collect();
    Ok(Report {
        name: src.name(),
        triangles: indices.len(),
        frames,
        threads: rayon::current_num_threads(),
        rows,
    })
}

/// The report as a text table.
#[must_use]
pub fn table(r: &Report) -> String {
    let mut s = format!(
        "{}: {} triangles, {} measured frames, {} threads\n\
         {:<18} {:>9} {:>9} {:>12} {:>9} {:>9} {:>11} {:>11}\n",
        r.name,
        r.triangles,
        r.frames.len(),
        r.threads,
        "rung",
        "wall ms",
        "cpu ms",
        "+collapse",
        "SAH rec",
        "work rec",
        "x rebuild",
        "x reb+coll"
    );
    for row in &r.rows {
        let _ = writeln!(
            s,
            "{:<18} {:>9.2} {:>9.2} {:>12.2} {:>9} {:>9} {:>11.3} {:>11.3}",
            row.rung,
            row.wall_ms,
            row.cpu_ms,
            row.wall_with_collapse_ms,
            pct(row.sah_recovered),
            pct(row.work_recovered),
            row.time_ratio,
            row.time_ratio_with_collapse
        );
    }
    s
}
