//! `bench`: every policy on the same frames and rays, the oracle's best schedule, and the
//! figures the charts draw.

use crate::bvh::{BuildParams, TraversalStats};
use crate::engine::oracle::{MeshCosts, SceneCosts};
use crate::engine::source::FrameSource;
use crate::engine::{
    Action, Engine, EngineConfig, MeshId, Policy, SceneHit, TlasPolicy, Traversal,
};
use crate::geom::{Aabb, Ray};
use crate::report::rays::camera_rays;
use serde::Serialize;
use std::time::Instant;

/// How many rays each frame casts (all from one camera looking at the scene's first frame).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RaySpec {
    /// About this many rays (a square image, cut to the count).
    Count(usize),
    /// A `w x h` image.
    Size(usize, usize),
}

impl RaySpec {
    /// The camera rays for a scene box.
    #[must_use]
    pub fn rays(self, bounds: &Aabb) -> Vec<Ray> {
        match self {
            RaySpec::Size(w, h) => camera_rays(bounds, w, h),
            RaySpec::Count(n) => {
                let w = (n as f64).sqrt().ceil().max(1.0) as usize;
                let h = n.div_ceil(w).max(1);
                let mut r = camera_rays(bounds, w, h);
                r.truncate(n.max(1));
                r
            }
        }
    }
}

/// What to run.
#[derive(Clone, Debug)]
pub struct Options {
    /// Policies to report (with the oracle, the always-refit and always-rebuild runs happen
    /// anyway: it needs their measurements).
    pub policies: Vec<Policy>,
    /// Rays per frame.
    pub rays: RaySpec,
    /// Builder of every tree.
    pub build: BuildParams,
    /// Top-level tree policy.
    pub tlas: TlasPolicy,
    /// Trace passes per frame; the fastest counts (fewer noisy frames).
    pub trace_repeats: usize,
    /// Rays per frame traced again with counters (nodes visited, triangles tested).
    pub counted_rays: usize,
    /// Builders for the speed-against-accuracy points (each rebuilding every frame).
    pub builders: Vec<BuildParams>,
    /// Frames each builder point runs over.
    pub builder_frames: usize,
    /// Compute the oracle (costs `frames` builds and `frames^2 / 2` refits).
    pub oracle: bool,
    /// Also run the default mesh policy under each top-level tree policy (refit, rebuild, the
    /// configured one) and report what the top-level tree costs.
    pub tlas_compare: bool,
    /// Which mesh trees the rays walk.
    pub traversal: Traversal,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            policies: Policy::standard_set(),
            rays: RaySpec::Size(256, 256),
            build: BuildParams::BINNED,
            tlas: EngineConfig::default().tlas,
            trace_repeats: 3,
            counted_rays: 1024,
            builders: vec![
                BuildParams::MEDIAN,
                BuildParams::binned(4),
                BuildParams::binned(8),
                BuildParams::BINNED,
                BuildParams::binned(32),
                BuildParams::SWEEP,
            ],
            builder_frames: 8,
            oracle: true,
            tlas_compare: true,
            traversal: Traversal::DEFAULT,
        }
    }
}

/// One frame of one policy.
#[derive(Clone, Debug, Serialize)]
pub struct FrameRow {
    /// Policy name.
    pub policy: String,
    /// Frame number (1-based; frame 0 is the pose the engine was built at).
    pub frame: usize,
    /// `refit`, `rebuild` (some mesh rebuilt) or `none`.
    pub action: Action,
    /// Pose time, ms.
    pub pose_ms: f64,
    /// Refit time, ms.
    pub refit_ms: f64,
    /// Rebuild time, ms.
    pub rebuild_ms: f64,
    /// Instance boxes and top-level tree, ms.
    pub tlas_ms: f64,
    /// Pose + refit + rebuild + TLAS, ms.
    pub update_ms: f64,
    /// Tracing the frame's rays, ms (fastest of the repeats).
    pub trace_ms: f64,
    /// Scene SAH cost.
    pub sah: f32,
    /// Trace-weighted SAH ratio to the last builds.
    pub sah_ratio: f32,
    /// Largest SAH ratio of a mesh.
    pub max_sah_ratio: f32,
    /// Largest ratio of a mesh's SAH to a fresh build's at this frame (the oracle's builds; 0
    /// without the oracle).
    pub fresh_ratio: f32,
    /// Largest fresh ratio as the engine estimated it (0 when the policy does not estimate).
    pub est_fresh_ratio: f32,
    /// Meshes rebuilt.
    pub rebuilds: u32,
    /// Meshes that went back to the tree their last rebuild replaced (`amortized`).
    pub reverts: u32,
    /// Rays traced.
    pub rays: u64,
    /// Millions of rays per second.
    pub mrays: f64,
    /// Measured nodes visited per ray (both levels).
    pub nodes_per_ray: f64,
    /// Measured triangles tested per ray.
    pub tris_per_ray: f64,
    /// What the SAH predicts for nodes per ray (rays that miss the scene's box cost nothing).
    pub predicted_nodes_per_ray: f64,
    /// What the SAH predicts for triangles per ray.
    pub predicted_tris_per_ray: f64,
}

/// Totals of one policy.
#[derive(Clone, Debug, Serialize)]
pub struct PolicySummary {
    /// Policy name.
    pub policy: String,
    /// True for the default policy.
    pub default: bool,
    /// Frames run.
    pub frames: usize,
    /// Update plus trace time over all frames, ms.
    pub total_ms: f64,
    /// Update time over all frames, ms.
    pub update_ms: f64,
    /// Trace time over all frames, ms.
    pub trace_ms: f64,
    /// Update time per frame, ms.
    pub update_ms_per_frame: f64,
    /// Trace time per frame, ms.
    pub trace_ms_per_frame: f64,
    /// Trace time per ray, microseconds.
    pub trace_us_per_ray: f64,
    /// Mesh rebuilds.
    pub rebuilds: u64,
    /// Returns to the tree a rebuild replaced.
    pub reverts: u64,
    /// Mean trace-weighted SAH ratio.
    pub mean_sah_ratio: f64,
    /// Largest SAH ratio of any mesh in any frame.
    pub max_sah_ratio: f32,
    /// Largest ratio to a fresh build of any mesh in any frame (0 without the oracle).
    pub max_fresh_ratio: f32,
    /// `total_ms` over the oracle's total (0 when the oracle was not computed).
    pub oracle_ratio: f64,
    /// Median over the frames of the pose time, ms.
    pub median_pose_ms: f64,
    /// Median of the mesh trees' update time (refit plus rebuild), ms.
    pub median_blas_ms: f64,
    /// Median of the top-level tree's time, ms.
    pub median_tlas_ms: f64,
    /// Median of the frame update (pose + mesh trees + top-level tree), ms.
    pub median_update_ms: f64,
    /// Median of the frame's trace time, ms.
    pub median_trace_ms: f64,
}

/// The top-level tree under one policy (mesh policy: the default).
#[derive(Clone, Debug, Serialize)]
pub struct TlasSummary {
    /// `refit`, `rebuild` or `threshold:R`.
    pub tlas: String,
    /// True for the engine's default.
    pub default: bool,
    /// Top-level tree time (instance boxes plus refit or rebuild) per frame, ms.
    pub tlas_ms_per_frame: f64,
    /// Trace time per frame, ms.
    pub trace_ms_per_frame: f64,
    /// Update plus trace over all frames, ms.
    pub total_ms: f64,
    /// Frames whose top-level tree was rebuilt.
    pub rebuilds: usize,
    /// Mean SAH ratio of the top-level tree to its last build.
    pub mean_sah_ratio: f64,
}

/// The best schedule in hindsight.
#[derive(Clone, Debug, Default, Serialize)]
pub struct OracleSummary {
    /// Modelled total time of the best schedule, ms.
    pub total_ms: f64,
    /// Rebuilds over all meshes.
    pub rebuilds: usize,
    /// For each deforming mesh, the frames it is rebuilt at.
    pub rebuild_frames: Vec<Vec<usize>>,
    /// Scale of the modelled extra trace time of a degraded tree (`extra = alpha * fresh *
    /// max(SAH ratio - 1, 0)`), fitted so that the modelled always-refit total is the measured one
    /// (1 when nothing could be fitted; see `engine::oracle`).
    pub alpha: f64,
    /// False when `alpha` could not be fitted (no deforming mesh, or no modelled degradation).
    pub alpha_fitted: bool,
    /// Modelled total of always refitting (calibrated), ms: equals `measured_refit_ms` when
    /// `alpha` was fitted and not clamped at 0.
    pub model_refit_ms: f64,
    /// Modelled total of always rebuilding, ms.
    pub model_rebuild_ms: f64,
    /// Modelled total of always refitting with `alpha = 1` (the uncalibrated SAH model), ms.
    pub model_refit_uncalibrated_ms: f64,
    /// Measured total (update plus trace) of the always-refit run, ms.
    pub measured_refit_ms: f64,
    /// Measured total of the always-rebuild run, ms.
    pub measured_rebuild_ms: f64,
    /// How costs were obtained.
    pub model: String,
}

/// A point of the speed-against-accuracy chart.
#[derive(Clone, Debug, Serialize)]
pub struct SpeedPoint {
    /// Builder (rebuilding every frame) or policy name.
    pub name: String,
    /// `builder` or `policy`.
    pub kind: String,
    /// Update time per frame, ms.
    pub update_ms_per_frame: f64,
    /// Trace time per ray, microseconds.
    pub trace_us_per_ray: f64,
    /// Mean SAH cost.
    pub sah: f64,
}

/// Everything `bench` measured.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// What was replayed.
    pub source: String,
    /// Triangles in the scene.
    pub triangles: usize,
    /// Deforming meshes.
    pub deforming_meshes: usize,
    /// Frames run per policy.
    pub frames: usize,
    /// Rays per frame.
    pub rays_per_frame: usize,
    /// Worker threads.
    pub threads: usize,
    /// Per policy, in the order asked.
    pub policies: Vec<PolicySummary>,
    /// The oracle.
    pub oracle: OracleSummary,
    /// The top-level tree under each of its policies (empty when not compared).
    pub tlas: Vec<TlasSummary>,
    /// Speed against accuracy: builders and policies.
    pub speed: Vec<SpeedPoint>,
    /// Every frame of every reported policy.
    pub per_frame: Vec<FrameRow>,
}

struct Run {
    config: EngineConfig,
    rows: Vec<FrameRow>,
    /// `[frame][mesh]` refit and rebuild ms, the mesh's share of the frame's trace, its SAH.
    refit: Vec<Vec<f64>>,
    rebuild: Vec<Vec<f64>>,
    share: Vec<Vec<f64>>,
    sah: Vec<Vec<f32>>,
    /// Per frame: top-level tree rebuilt, its SAH ratio.
    tlas: Vec<(bool, f32)>,
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Runs every configuration over every frame in lockstep: each frame is posed into every engine
/// and updated, then the engines trace the frame's rays in turn, `trace_repeats` rounds in a
/// rotating order, each keeping its fastest pass. Interleaving puts every configuration under
/// the same load (this machine is shared), so differences between their times are the trees'.
fn run_lockstep(
    src: &mut dyn FrameSource,
    configs: &[EngineConfig],
    rays: &[Ray],
    opts: &Options,
    frames: usize,
) -> Vec<Run> {
    let deforming = src.deforming().len();
    let mut engines: Vec<Engine> = configs.iter().map(|&c| src.build(0, c)).collect();
    let mut hits: Vec<Option<SceneHit>> = vec![None; rays.len()];
    let step = (rays.len() / opts.counted_rays.max(1)).max(1);
    let mut runs: Vec<Run> = configs
        .iter()
        .map(|&config| Run {
            config,
            rows: Vec::with_capacity(frames),
            refit: vec![vec![0.0; deforming]; frames + 1],
            rebuild: vec![vec![0.0; deforming]; frames + 1],
            share: vec![vec![0.0; deforming]; frames + 1],
            sah: vec![vec![0.0; deforming]; frames + 1],
            tlas: Vec::with_capacity(frames),
        })
        .collect();
    // Warm-up: one untimed pass each.
    for e in &engines {
        e.trace_closest(rays, &mut hits);
    }
    let n = engines.len();
    let mut best = vec![f64::INFINITY; n];
    for f in 1..=frames {
        for e in &mut engines {
            src.advance(e, f);
            e.update();
        }
        best.fill(f64::INFINITY);
        for rep in 0..opts.trace_repeats.max(1) {
            for k in 0..n {
                let i = (k + rep + f) % n;
                let t = Instant::now();
                engines[i].trace_closest(rays, &mut hits);
                best[i] = best[i].min(ms(t));
            }
        }
        for ((e, run), &best) in engines.iter_mut().zip(&mut runs).zip(&best) {
            e.record_trace(best, rays.len() as u64);
            record_frame(e, src.deforming(), run, rays, step, f);
        }
    }
    runs
}

/// Appends frame `f` of engine `e` (updated and traced) to `run`.
fn record_frame(
    e: &Engine,
    deforming: &[MeshId],
    run: &mut Run,
    rays: &[Ray],
    step: usize,
    f: usize,
) {
    let s = *e.frame_stats();
    let mut counted = TraversalStats::default();
    let mut n = 0u64;
    let mut in_box = 0u64;
    let root = e.bounds();
    for r in rays.iter().step_by(step) {
        let _ = e.closest_hit_counted(r, &mut counted);
        n += 1;
        if r.hit_box(root.min, root.max, r.tmax).is_some() {
            in_box += 1;
        }
    }
    let (pn, pt) = e.predicted_work();
    let p_hit = in_box as f64 / n.max(1) as f64;
    for (k, m) in deforming.iter().enumerate() {
        let ms = e.mesh_stats(*m);
        run.refit[f][k] = ms.refit_ms;
        run.rebuild[f][k] = ms.rebuild_ms;
        run.share[f][k] = e.mesh_trace_share(*m);
        run.sah[f][k] = ms.sah;
    }
    run.tlas.push((s.tlas_rebuilt, s.tlas_sah_ratio));
    run.rows.push(FrameRow {
        policy: run.config.policy.to_string(),
        frame: f,
        action: s.action,
        pose_ms: s.pose_ms,
        refit_ms: s.refit_ms,
        rebuild_ms: s.rebuild_ms,
        tlas_ms: s.tlas_ms,
        update_ms: s.update_ms,
        trace_ms: s.trace_ms,
        sah: s.sah,
        sah_ratio: s.sah_ratio,
        max_sah_ratio: s.max_sah_ratio,
        fresh_ratio: 0.0,
        est_fresh_ratio: s.max_fresh_ratio,
        rebuilds: s.rebuilds,
        reverts: s.reverts,
        rays: s.rays,
        mrays: s.mrays,
        nodes_per_ray: counted.nodes as f64 / n.max(1) as f64,
        tris_per_ray: counted.prims as f64 / n.max(1) as f64,
        predicted_nodes_per_ray: pn * p_hit,
        predicted_tris_per_ray: pt * p_hit,
    });
}

fn summarize(policy: Policy, rows: &[FrameRow], oracle_total: f64) -> PolicySummary {
    let n = rows.len().max(1) as f64;
    let update: f64 = rows.iter().map(|r| r.update_ms).sum();
    let trace: f64 = rows.iter().map(|r| r.trace_ms).sum();
    let rays: u64 = rows.iter().map(|r| r.rays).sum();
    let total = update + trace;
    PolicySummary {
        policy: policy.to_string(),
        default: policy == Policy::DEFAULT,
        frames: rows.len(),
        total_ms: total,
        update_ms: update,
        trace_ms: trace,
        update_ms_per_frame: update / n,
        trace_ms_per_frame: trace / n,
        trace_us_per_ray: if rays > 0 {
            trace * 1e3 / rays as f64
        } else {
            0.0
        },
        rebuilds: rows.iter().map(|r| u64::from(r.rebuilds)).sum(),
        reverts: rows.iter().map(|r| u64::from(r.reverts)).sum(),
        mean_sah_ratio: rows.iter().map(|r| f64::from(r.sah_ratio)).sum::<f64>() / n,
        max_sah_ratio: rows.iter().map(|r| r.max_sah_ratio).fold(1.0, f32::max),
        max_fresh_ratio: rows.iter().map(|r| r.fresh_ratio).fold(0.0, f32::max),
        oracle_ratio: if oracle_total > 0.0 {
            total / oracle_total
        } else {
            0.0
        },
        median_pose_ms: median(rows.iter().map(|r| r.pose_ms)),
        median_blas_ms: median(rows.iter().map(|r| r.refit_ms + r.rebuild_ms)),
        median_tlas_ms: median(rows.iter().map(|r| r.tlas_ms)),
        median_update_ms: median(rows.iter().map(|r| r.update_ms)),
        median_trace_ms: median(rows.iter().map(|r| r.trace_ms)),
    }
}

/// The median (the mean of the two middle values for an even count; 0 when empty).
fn median(v: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = v.collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Runs the whole benchmark; `progress` hears what starts.
pub fn run(src: &mut dyn FrameSource, opts: &Options, mut progress: impl FnMut(&str)) -> Report {
    let frames = src.frames();
    let config = |policy| EngineConfig {
        build: opts.build,
        policy,
        tlas: opts.tlas,
        traversal: opts.traversal,
        ..EngineConfig::default()
    };
    let rays = {
        let e = src.build(0, config(Policy::Refit));
        opts.rays.rays(&e.bounds())
    };
    let deforming = src.deforming().len();

    // The measured runs: the asked policies, plus always-refit and always-rebuild when the
    // oracle needs them.
    let mut wanted = opts.policies.clone();
    if opts.oracle {
        for p in [Policy::Refit, Policy::Rebuild] {
            if !wanted.contains(&p) {
                wanted.push(p);
            }
        }
    }
    // The top-level tree comparison: the default mesh policy under each top-level policy.
    let mut tlas_configs = Vec::new();
    if opts.tlas_compare {
        for t in [TlasPolicy::Refit, TlasPolicy::Rebuild, opts.tlas] {
            let c = EngineConfig {
                tlas: t,
                ..config(Policy::DEFAULT)
            };
            if !tlas_configs.contains(&c) {
                tlas_configs.push(c);
            }
        }
    }
    let mut configs: Vec<EngineConfig> = wanted.iter().map(|&p| config(p)).collect();
    for c in &tlas_configs {
        if !configs.contains(c) {
            configs.push(*c);
        }
    }
    progress(&format!(
        "{} configurations in lockstep: {}",
        configs.len(),
        configs
            .iter()
            .map(|c| format!("{}/tlas {}", c.policy, tlas_name(c.tlas)))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    let mut all_runs = run_lockstep(src, &configs, &rays, opts, frames);
    let runs = &mut all_runs[..wanted.len()];

    let mut oracle = OracleSummary::default();
    let mut oracle_total = 0.0;
    if opts.oracle && frames > 0 {
        let find = |p: Policy| &runs[wanted.iter().position(|&q| q == p).expect("run")];
        let (refit_run, rebuild_run) = (find(Policy::Refit), find(Policy::Rebuild));
        progress("oracle: building at every frame, refitting through the later ones");
        // sah[mesh][b][f - b]
        let mut sah = vec![vec![Vec::new(); frames + 1]; deforming];
        for b in 0..=frames {
            let mut e = src.build(b, config(Policy::Refit));
            let ids = src.deforming().to_vec();
            for (row, m) in sah.iter_mut().zip(&ids) {
                row[b].push(e.mesh_stats(*m).sah);
            }
            for f in b + 1..=frames {
                src.advance(&mut e, f);
                e.update();
                for (row, m) in sah.iter_mut().zip(&ids) {
                    row[b].push(e.mesh_stats(*m).sah);
                }
            }
        }
        // Costs no schedule changes: pose and top-level tree (fastest over the runs), and
        // tracing with fresh trees.
        let mut fixed = 0.0;
        for f in 1..=frames {
            let pose = runs
                .iter()
                .map(|r| r.rows[f - 1].pose_ms)
                .fold(f64::INFINITY, f64::min);
            let tlas = runs
                .iter()
                .map(|r| r.rows[f - 1].tlas_ms)
                .fold(f64::INFINITY, f64::min);
            fixed += pose + tlas + rebuild_run.rows[f - 1].trace_ms;
        }
        let mut fresh: Vec<Vec<f32>> = Vec::new();
        let mut scene = SceneCosts {
            fixed_ms: fixed,
            meshes: Vec::with_capacity(deforming),
        };
        for (k, sah) in sah.into_iter().enumerate() {
            let c = MeshCosts {
                refit_ms: (0..=frames).map(|f| refit_run.refit[f][k]).collect(),
                rebuild_ms: (0..=frames).map(|f| rebuild_run.rebuild[f][k]).collect(),
                fresh_trace_ms: (0..=frames)
                    .map(|f| {
                        if f == 0 {
                            0.0
                        } else {
                            rebuild_run.rows[f - 1].trace_ms * rebuild_run.share[f][k]
                        }
                    })
                    .collect(),
                sah,
            };
            fresh.push((0..=frames).map(|f| c.sah[f][0]).collect::<Vec<f32>>());
            scene.meshes.push(c);
        }
        let measured = |r: &Run| r.rows.iter().map(|x| x.update_ms + x.trace_ms).sum::<f64>();
        oracle.measured_refit_ms = measured(refit_run);
        oracle.measured_rebuild_ms = measured(rebuild_run);
        let cal = scene.calibrate(oracle.measured_refit_ms);
        let (total, schedules) = scene.best(cal.alpha);
        oracle_total = total;
        oracle.total_ms = total;
        oracle.alpha = cal.alpha;
        oracle.alpha_fitted = cal.fitted;
        oracle.model_refit_ms = cal.model_refit_ms;
        oracle.model_rebuild_ms = cal.model_rebuild_ms;
        oracle.model_refit_uncalibrated_ms = cal.uncalibrated_refit_ms;
        for s in &schedules {
            oracle.rebuilds += s.rebuilds();
            oracle
                .rebuild_frames
                .push((1..=frames).filter(|&f| s.rebuild[f]).collect());
        }
        oracle.model = "refit and rebuild times measured per frame (always-refit and \
            always-rebuild runs); trace time modelled as the always-rebuild run's measured \
            trace time plus, per mesh, alpha x its share of it (by SAH-expected trace cost) x \
            max(SAH ratio - 1, 0), the ratio of the tree built at b refitted to f over the tree built \
            at f; alpha fitted so the modelled always-refit total equals the measured one; \
            schedules refit or rebuild only (no going back to an older tree)"
            .into();
        // The true fresh ratio of every run's trees (same positions, same deterministic build).
        for run in all_runs.iter_mut() {
            for (f, row) in (1..=frames).zip(run.rows.iter_mut()) {
                row.fresh_ratio = fresh
                    .iter()
                    .zip(&run.sah[f])
                    .map(|(fr, &s)| if fr[f] > 0.0 { s / fr[f] } else { 1.0 })
                    .fold(1.0, f32::max);
            }
        }
    }
    let runs = &all_runs[..wanted.len()];

    let mut policies = Vec::new();
    let mut per_frame = Vec::new();
    let mut speed = Vec::new();
    for (p, r) in wanted.iter().zip(runs) {
        if !opts.policies.contains(p) {
            continue;
        }
        let s = summarize(*p, &r.rows, oracle_total);
        speed.push(SpeedPoint {
            name: p.to_string(),
            kind: "policy".into(),
            update_ms_per_frame: s.update_ms_per_frame,
            trace_us_per_ray: s.trace_us_per_ray,
            sah: r.rows.iter().map(|x| f64::from(x.sah)).sum::<f64>() / r.rows.len().max(1) as f64,
        });
        policies.push(s);
        per_frame.extend(r.rows.iter().cloned());
    }
    let bf = opts.builder_frames.min(frames);
    if bf > 0 {
        for b in &opts.builders {
            progress(&format!("builder {}", b.name()));
            let cfg = EngineConfig {
                build: *b,
                policy: Policy::Rebuild,
                tlas: opts.tlas,
                traversal: opts.traversal,
                ..EngineConfig::default()
            };
            let r = run_lockstep(src, &[cfg], &rays, opts, bf).remove(0);
            let s = summarize(Policy::Rebuild, &r.rows, 0.0);
            speed.push(SpeedPoint {
                name: b.name(),
                kind: "builder".into(),
                update_ms_per_frame: s.update_ms_per_frame,
                trace_us_per_ray: s.trace_us_per_ray,
                sah: r.rows.iter().map(|x| f64::from(x.sah)).sum::<f64>() / bf as f64,
            });
        }
    }
    let tlas = tlas_configs
        .iter()
        .map(|c| {
            let r = &all_runs[configs.iter().position(|x| x == c).expect("run")];
            let n = r.rows.len().max(1) as f64;
            TlasSummary {
                tlas: tlas_name(c.tlas),
                default: c.tlas == EngineConfig::default().tlas,
                tlas_ms_per_frame: r.rows.iter().map(|x| x.tlas_ms).sum::<f64>() / n,
                trace_ms_per_frame: r.rows.iter().map(|x| x.trace_ms).sum::<f64>() / n,
                total_ms: r.rows.iter().map(|x| x.update_ms + x.trace_ms).sum(),
                rebuilds: r.tlas.iter().filter(|t| t.0).count(),
                mean_sah_ratio: r.tlas.iter().map(|t| f64::from(t.1)).sum::<f64>() / n,
            }
        })
        .collect();
    Report {
        source: src.name(),
        triangles: src.triangle_count(),
        deforming_meshes: deforming,
        frames,
        rays_per_frame: rays.len(),
        threads: rayon::current_num_threads(),
        policies,
        oracle,
        tlas,
        speed,
        per_frame,
    }
}

/// Name of a top-level tree policy as the reports print it.
#[must_use]
pub fn tlas_name(t: TlasPolicy) -> String {
    match t {
        TlasPolicy::Refit => "refit".into(),
        TlasPolicy::Rebuild => "rebuild".into(),
        TlasPolicy::Threshold(r) => format!("threshold:{r}"),
    }
}

/// The per-frame rows as CSV (header first).
#[must_use]
pub fn to_csv(rows: &[FrameRow]) -> String {
    let mut s = String::from(
        "policy,frame,action,pose_ms,refit_ms,rebuild_ms,tlas_ms,update_ms,trace_ms,sah,\
         sah_ratio,max_sah_ratio,fresh_ratio,est_fresh_ratio,rebuilds,rays,mrays,nodes_per_ray,\
         tris_per_ray,predicted_nodes_per_ray,predicted_tris_per_ray,reverts\n",
    );
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{:.3},{:.2},{:.2},{:.2},{:.2},{}\n",
            r.policy,
            r.frame,
            r.action.name(),
            r.pose_ms,
            r.refit_ms,
            r.rebuild_ms,
            r.tlas_ms,
            r.update_ms,
            r.trace_ms,
            r.sah,
            r.sah_ratio,
            r.max_sah_ratio,
            r.fresh_ratio,
            r.est_fresh_ratio,
            r.rebuilds,
            r.rays,
            r.mrays,
            r.nodes_per_ray,
            r.tris_per_ray,
            r.predicted_nodes_per_ray,
            r.predicted_tris_per_ray,
            r.reverts
        ));
    }
    s
}

/// The summary table, one line per policy and one for the oracle.
#[must_use]
pub fn summary_table(r: &Report) -> String {
    let mut s = format!(
        "{}: {} triangles, {} deforming mesh(es), {} frames, {} rays/frame, {} thread(s)\n",
        r.source, r.triangles, r.deforming_meshes, r.frames, r.rays_per_frame, r.threads
    );
    s.push_str(&format!(
        "{:<14} {:>10} {:>10} {:>10} {:>9} {:>9} {:>8} {:>8} {:>8} {:>9} {:>8}\n",
        "policy",
        "total ms",
        "update ms",
        "trace ms",
        "upd/fr",
        "trace/fr",
        "rebuilds",
        "mean SAH",
        "max SAH",
        "max fresh",
        "/oracle"
    ));
    for p in &r.policies {
        s.push_str(&format!(
            "{:<14} {:>10.2} {:>10.2} {:>10.2} {:>9.3} {:>9.3} {:>8} {:>8.3} {:>8.3} {:>9.3} {:>8.3}\n",
            format!("{}{}", p.policy, if p.default { "*" } else { "" }),
            p.total_ms,
            p.update_ms,
            p.trace_ms,
            p.update_ms_per_frame,
            p.trace_ms_per_frame,
            if p.reverts > 0 {
                format!("{} ({})", p.rebuilds, p.reverts)
            } else {
                p.rebuilds.to_string()
            },
            p.mean_sah_ratio,
            p.max_sah_ratio,
            p.max_fresh_ratio,
            p.oracle_ratio
        ));
    }
    if r.oracle.total_ms > 0.0 {
        let o = &r.oracle;
        s.push_str(&format!(
            "{:<14} {:>10.2} {:>54}\n",
            "oracle",
            o.total_ms,
            format!("{} rebuilds", o.rebuilds),
        ));
        s.push_str(&format!(
            "oracle model: alpha {:.3}{} (extra trace = alpha x fresh trace x max(SAH ratio - 1, 0)); \
             always-refit modelled {:.2} / measured {:.2} ms (alpha = 1: {:.2}); \
             always-rebuild modelled {:.2} / measured {:.2} ms\n",
            o.alpha,
            if o.alpha_fitted { "" } else { " (not fitted)" },
            o.model_refit_ms,
            o.measured_refit_ms,
            o.model_refit_uncalibrated_ms,
            o.model_rebuild_ms,
            o.measured_rebuild_ms
        ));
    }
    s.push_str(
        "* default policy; SAH: ratio to the last build; fresh: ratio to a fresh build now; \
         rebuilds (n): n times back to the tree a rebuild replaced\n",
    );
    s.push_str(&format!(
        "update against trace per frame (medians over {} frames; update = pose + mesh trees + \
         top-level tree; mean update includes rebuilds spread over the frames):\n\
         {:<14} {:>9} {:>9} {:>9} {:>10} {:>10} {:>10} {:>10}  update < trace\n",
        r.frames, "policy", "pose", "meshes", "tlas", "update", "trace", "upd/trace", "mean upd"
    ));
    for p in &r.policies {
        let ratio = if p.median_trace_ms > 0.0 {
            p.median_update_ms / p.median_trace_ms
        } else {
            f64::INFINITY
        };
        s.push_str(&format!(
            "{:<14} {:>9.3} {:>9.3} {:>9.4} {:>10.3} {:>10.3} {:>10.3} {:>10.3}  {}\n",
            format!("{}{}", p.policy, if p.default { "*" } else { "" }),
            p.median_pose_ms,
            p.median_blas_ms,
            p.median_tlas_ms,
            p.median_update_ms,
            p.median_trace_ms,
            ratio,
            p.update_ms_per_frame,
            match (ratio < 1.0, p.update_ms_per_frame < p.trace_ms_per_frame) {
                (true, true) => "yes (median and mean)",
                (true, false) => "median only",
                (false, true) => "mean only",
                (false, false) => "no",
            }
        ));
    }
    if !r.tlas.is_empty() {
        s.push_str(&format!(
            "top-level tree ({} policy for meshes):\n{:<14} {:>10} {:>9} {:>9} {:>8} {:>9}\n",
            Policy::DEFAULT,
            "tlas",
            "total ms",
            "tlas/fr",
            "trace/fr",
            "rebuilds",
            "mean SAH"
        ));
        for t in &r.tlas {
            s.push_str(&format!(
                "{:<14} {:>10.2} {:>9.4} {:>9.3} {:>8} {:>9.3}\n",
                format!("{}{}", t.tlas, if t.default { "*" } else { "" }),
                t.total_ms,
                t.tlas_ms_per_frame,
                t.trace_ms_per_frame,
                t.rebuilds,
                t.mean_sah_ratio
            ));
        }
    }
    s
}

/// The four charts of a report: `(file stem, chart)`.
#[must_use]
pub fn charts(r: &Report) -> Vec<(&'static str, crate::report::charts::Chart)> {
    use crate::report::charts::{Chart, Series};
    let by_policy = |f: &dyn Fn(&FrameRow) -> f64, marks: bool| -> Vec<Series> {
        r.policies
            .iter()
            .map(|p| {
                let rows: Vec<&FrameRow> = r
                    .per_frame
                    .iter()
                    .filter(|x| x.policy == p.policy)
                    .collect();
                Series {
                    name: format!("{}{}", p.policy, if p.default { " *" } else { "" }),
                    points: rows.iter().map(|x| (x.frame as f64, f(x))).collect(),
                    line: true,
                    marks: if marks {
                        rows.iter()
                            .filter(|x| x.rebuilds > 0)
                            .map(|x| (x.frame as f64, f(x)))
                            .collect()
                    } else {
                        Vec::new()
                    },
                }
            })
            .collect()
    };
    let sah = Chart {
        title: format!("SAH ratio to last build: {}", short(&r.source)),
        x_label: "frame".into(),
        y_label: "max SAH ratio".into(),
        series: by_policy(&|x| f64::from(x.max_sah_ratio), true),
        note: "rings: rebuilds".into(),
        ..Chart::default()
    };
    let time = Chart {
        title: format!("time per frame (update + trace): {}", short(&r.source)),
        x_label: "frame".into(),
        y_label: "ms".into(),
        series: by_policy(&|x| x.update_ms + x.trace_ms, true),
        log_y: true,
        note: "rings: rebuilds".into(),
        ..Chart::default()
    };
    let mut speed_series: Vec<Series> = Vec::new();
    for p in &r.speed {
        speed_series.push(Series {
            name: format!("{} {}", p.kind, p.name),
            points: vec![(p.update_ms_per_frame, p.trace_us_per_ray)],
            line: false,
            marks: Vec::new(),
        });
    }
    let speed = Chart {
        title: "speed against accuracy".into(),
        x_label: "update ms per frame".into(),
        y_label: "trace us per ray".into(),
        series: speed_series,
        log_x: true,
        ..Chart::default()
    };
    let predicted = Chart {
        title: "SAH-predicted against measured traversal cost".into(),
        x_label: "predicted nodes + triangles per ray".into(),
        y_label: "measured per ray".into(),
        series: r
            .policies
            .iter()
            .map(|p| Series {
                name: p.policy.clone(),
                points: r
                    .per_frame
                    .iter()
                    .filter(|x| x.policy == p.policy)
                    .map(|x| {
                        (
                            x.predicted_nodes_per_ray + x.predicted_tris_per_ray,
                            x.nodes_per_ray + x.tris_per_ray,
                        )
                    })
                    .collect(),
                line: false,
                marks: Vec::new(),
            })
            .collect(),
        diagonal: true,
        note: "grey: y = x".into(),
        ..Chart::default()
    };
    vec![
        ("sah_ratio", sah),
        ("frame_time", time),
        ("speed_accuracy", speed),
        ("predicted_vs_measured", predicted),
    ]
}

fn short(s: &str) -> String {
    std::path::Path::new(s)
        .file_name()
        .map_or_else(|| s.to_string(), |n| n.to_string_lossy().into_owned())
}

/// A file or animation of the sweep that gave no report.
#[derive(Clone, Debug, Serialize)]
pub struct SweepFailure {
    /// The file, and the animation when the file loaded.
    pub source: String,
    /// Why.
    pub error: String,
}

/// One policy over the sweep's rows (only rows with an oracle count).
#[derive(Clone, Debug, Serialize)]
pub struct PolicyVerdict {
    /// Policy name.
    pub policy: String,
    /// True for the default policy.
    pub default: bool,
    /// Rows (file and animation) counted.
    pub rows: usize,
    /// Mean total time over the oracle's.
    pub mean_ratio: f64,
    /// Largest total time over the oracle's.
    pub worst_ratio: f64,
    /// The row of the largest ratio.
    pub worst_source: String,
    /// Rows more than 10% above the oracle.
    pub over_10pct: Vec<String>,
    /// Largest ratio over the rows with a deforming mesh (the others run the same trees under
    /// every policy: their ratios are timing noise); 0 without such rows.
    pub worst_deforming_ratio: f64,
    /// The row of `worst_deforming_ratio`.
    pub worst_deforming_source: String,
}

/// What a sweep's table says, computed from it.
#[derive(Clone, Debug, Serialize)]
pub struct SweepConclusion {
    /// Per policy, in the table's order.
    pub policies: Vec<PolicyVerdict>,
    /// The policy with the lowest worst ratio (none without rows).
    pub lowest_worst: Option<String>,
    /// The default policy's verdict: within 10% of the oracle on every row (false without
    /// rows).
    pub default_within_10pct: bool,
    /// Rows that gave no report (load or run failures).
    pub failures: usize,
}

/// Everything `bench --all` produced.
#[derive(Clone, Debug, Serialize)]
pub struct Sweep {
    /// One report per file and animation.
    pub reports: Vec<Report>,
    /// Files that did not load, animations that did not run.
    pub failed: Vec<SweepFailure>,
    /// Files without animation (not run).
    pub not_animated: Vec<String>,
    /// What the table says.
    pub conclusion: SweepConclusion,
}

impl Sweep {
    /// Collects the sweep's results and computes its conclusion.
    #[must_use]
    pub fn new(reports: Vec<Report>, failed: Vec<SweepFailure>, not_animated: Vec<String>) -> Self {
        let conclusion = sweep_conclusion(&reports, failed.len());
        Self {
            reports,
            failed,
            not_animated,
            conclusion,
        }
    }
}

/// Per policy, the mean and worst ratio to the oracle over the reports that have one; which
/// policy's worst is lowest; whether the default stays within 10% everywhere.
#[must_use]
pub fn sweep_conclusion(reports: &[Report], failures: usize) -> SweepConclusion {
    let mut policies: Vec<PolicyVerdict> = Vec::new();
    for r in reports.iter().filter(|r| r.oracle.total_ms > 0.0) {
        for p in &r.policies {
            let k = match policies.iter().position(|v| v.policy == p.policy) {
                Some(k) => k,
                None => {
                    policies.push(PolicyVerdict {
                        policy: p.policy.clone(),
                        default: p.default,
                        rows: 0,
                        mean_ratio: 0.0,
                        worst_ratio: 0.0,
                        worst_source: String::new(),
                        over_10pct: Vec::new(),
                        worst_deforming_ratio: 0.0,
                        worst_deforming_source: String::new(),
                    });
                    policies.len() - 1
                }
            };
            let v = &mut policies[k];
            v.rows += 1;
            v.mean_ratio += p.oracle_ratio;
            if p.oracle_ratio > v.worst_ratio {
                v.worst_ratio = p.oracle_ratio;
                v.worst_source.clone_from(&r.source);
            }
            if p.oracle_ratio > 1.10 {
                v.over_10pct.push(r.source.clone());
            }
            if r.deforming_meshes > 0 && p.oracle_ratio > v.worst_deforming_ratio {
                v.worst_deforming_ratio = p.oracle_ratio;
                v.worst_deforming_source.clone_from(&r.source);
            }
        }
    }
    for v in &mut policies {
        v.mean_ratio /= v.rows.max(1) as f64;
    }
    let lowest_worst = policies
        .iter()
        .min_by(|a, b| a.worst_ratio.total_cmp(&b.worst_ratio))
        .map(|v| v.policy.clone());
    let default_within_10pct = policies
        .iter()
        .find(|v| v.default)
        .is_some_and(|v| v.rows > 0 && v.over_10pct.is_empty());
    SweepConclusion {
        policies,
        lowest_worst,
        default_within_10pct,
        failures,
    }
}

/// The conclusion as text.
#[must_use]
pub fn conclusion_text(c: &SweepConclusion) -> String {
    let mut s = String::from("Conclusion (computed from the rows above):\n");
    if c.policies.is_empty() {
        s.push_str("  no row has an oracle: nothing to conclude\n");
    }
    s.push_str(&format!(
        "  {:<16} {:>5} {:>7} {:>7}  worst row; worst of the rows with a deforming mesh\n",
        "policy", "rows", "mean", "worst"
    ));
    for v in &c.policies {
        s.push_str(&format!(
            "  {:<16} {:>5} {:>7.3} {:>7.3}  {}; {:.3} {}\n",
            format!("{}{}", v.policy, if v.default { "*" } else { "" }),
            v.rows,
            v.mean_ratio,
            v.worst_ratio,
            v.worst_source,
            v.worst_deforming_ratio,
            v.worst_deforming_source
        ));
    }
    if let Some(best) = &c.lowest_worst
        && let Some(v) = c.policies.iter().find(|v| &v.policy == best)
    {
        s.push_str(&format!(
            "  lowest worst ratio: {} ({:.3})\n",
            v.policy, v.worst_ratio
        ));
    }
    if let Some(d) = c.policies.iter().find(|v| v.default) {
        if c.default_within_10pct {
            s.push_str(&format!(
                "  default {}: within 10% of the oracle on every row ({} rows; worst {:.3}, {})\n",
                d.policy, d.rows, d.worst_ratio, d.worst_source
            ));
        } else {
            s.push_str(&format!(
                "  default {}: NOT within 10% of the oracle on {} of {} rows ({}); worst {:.3}, {}\n",
                d.policy,
                d.over_10pct.len(),
                d.rows,
                d.over_10pct.join(", "),
                d.worst_ratio,
                d.worst_source
            ));
        }
    } else if !c.policies.is_empty() {
        s.push_str("  the default policy was not run\n");
    }
    if c.failures > 0 {
        s.push_str(&format!(
            "  {} file(s) or animation(s) gave no row (see above): not counted\n",
            c.failures
        ));
    }
    s.push_str(
        "  (rows without a deforming mesh run the same trees under every policy: their spread \
         around 1 shows the run's timing noise. Ratios within a few percent of 1, either side, \
         are timing noise on a shared machine; \
         the oracle's schedules refit or rebuild only, so a policy that goes back to an older \
         tree can come out below 1)\n",
    );
    s
}

/// The sweep table: per file and animation, per policy, total time over the oracle's; then the
/// worst ratio of each policy, the top-level tree comparison (total time over the best
/// top-level policy's on that file), the rows that failed, and the conclusion computed from the
/// rows ([`sweep_conclusion`]).
#[must_use]
pub fn sweep_table(sweep: &Sweep) -> String {
    let mut s = sweep_rows(&sweep.reports);
    for f in &sweep.failed {
        s.push_str(&format!("FAILED {}: {}\n", f.source, f.error));
    }
    for n in &sweep.not_animated {
        s.push_str(&format!("not run (no animation): {n}\n"));
    }
    s.push('\n');
    s.push_str(&conclusion_text(&sweep.conclusion));
    s
}

fn sweep_rows(reports: &[Report]) -> String {
    let Some(first) = reports.first() else {
        return "no animated files\n".into();
    };
    let names: Vec<String> = first
        .policies
        .iter()
        .map(|p| format!("{}{}", p.policy, if p.default { "*" } else { "" }))
        .collect();
    let tlas_names: Vec<String> = first
        .tlas
        .iter()
        .map(|t| format!("tlas {}{}", t.tlas, if t.default { "*" } else { "" }))
        .collect();
    let mut s = format!(
        "total time / oracle ({} frames, {} rays/frame, {} thread(s); * default)\n",
        first.frames, first.rays_per_frame, first.threads
    );
    s.push_str(&format!(
        "{:<44} {:>7} {:>4}",
        "file [animation]", "tris", "dfm"
    ));
    for n in names.iter().chain(&tlas_names) {
        s.push_str(&format!(" {:>w$}", n, w = n.len().max(8)));
    }
    s.push('\n');
    let mut worst = vec![0.0f64; names.len()];
    let mut worst_tlas = vec![0.0f64; tlas_names.len()];
    for r in reports {
        let mut name = r.source.clone();
        if name.len() > 44 {
            name = format!("...{}", &name[name.len() - 41..]);
        }
        s.push_str(&format!(
            "{:<44} {:>7} {:>4}",
            name, r.triangles, r.deforming_meshes
        ));
        for (k, n) in names.iter().enumerate() {
            let v = r.policies.get(k).map_or(0.0, |p| p.oracle_ratio);
            worst[k] = worst[k].max(v);
            s.push_str(&format!(" {:>w$.3}", v, w = n.len().max(8)));
        }
        let best_tlas = r
            .tlas
            .iter()
            .map(|t| t.total_ms)
            .fold(f64::INFINITY, f64::min);
        for (k, n) in tlas_names.iter().enumerate() {
            let v = r.tlas.get(k).map_or(0.0, |t| t.total_ms / best_tlas);
            worst_tlas[k] = worst_tlas[k].max(v);
            s.push_str(&format!(" {:>w$.3}", v, w = n.len().max(8)));
        }
        s.push('\n');
    }
    s.push_str(&format!("{:<44} {:>7} {:>4}", "worst", "", ""));
    for (v, n) in worst.iter().zip(&names) {
        s.push_str(&format!(" {:>w$.3}", v, w = n.len().max(8)));
    }
    for (v, n) in worst_tlas.iter().zip(&tlas_names) {
        s.push_str(&format!(" {:>w$.3}", v, w = n.len().max(8)));
    }
    s.push_str("\n(tlas columns: total time over the best top-level policy on that file)\n");
    s
}
