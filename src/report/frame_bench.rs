//! `bench`: every policy on the same frames and rays, the oracle's best schedule, and the
//! figures the charts draw.

use crate::bvh::BuildParams;
use crate::cputime::{CpuClock, Elapsed};
use crate::engine::oracle::{MeshCosts, SceneCosts};
use crate::engine::policy::{LADDER_OPTIMIZE, LADDER_PARTIAL, PolicyState};
use crate::engine::ray_work::{SAMPLE_MAX, SAMPLE_STRIDE};
use crate::engine::source::FrameSource;
use crate::engine::{
    Action, CostMeasure, Decision, Engine, EngineConfig, EngineMemory, MeshId, Policy, Prices,
    Query, SceneHit, Timing, TlasPolicy, Traversal, WorkerPriority,
};
use crate::geom::{Aabb, Ray};
use crate::report::all_pairs::{self, SampledFrame};
use crate::report::rays::camera_rays;
use serde::Serialize;

/// A run whose threads waited for a core more than this share of their CPU time is flagged
/// busy: its wall-clock figures are disturbed.
pub const BUSY_SHARE: f64 = 0.10;

/// How many rays each frame casts (all from one camera looking at the scene's first frame).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RaySpec {
    /// About this many rays (a square image, cut to the count).
    Count(usize),
    /// A `w x h` image.
    Size(usize, usize),
    /// This many rays of a spinning lidar-like fan above the scene, turning from frame to
    /// frame ([`crate::report::rays::lidar_rays`]).
    Lidar(usize),
}

impl RaySpec {
    /// Frame `frame`'s rays for a scene box (the camera's are the same every frame), into
    /// `out`.
    pub fn frame_rays(self, bounds: &Aabb, frame: usize, out: &mut Vec<Ray>) {
        match self {
            RaySpec::Lidar(n) => crate::report::rays::lidar_rays(bounds, n, frame, out),
            _ => {
                if out.is_empty() {
                    *out = self.rays(bounds);
                }
            }
        }
    }

    /// Reorders a camera image's rays (row-major, whole rows) into 16x8 tiles, so that each run
    /// of 128 is one packet's square of the image ([`crate::bvh::image_tiles`]); the
    /// lidar's fan and cut images are left as they are.
    pub fn in_tiles(self, rays: &mut Vec<Ray>) {
        let Some((w, h)) = self.image_size() else {
            return;
        };
        if w * h != rays.len() {
            return;
        }
        let mut tiled = Vec::with_capacity(rays.len());
        crate::bvh::image_tiles(w, h, |idx| tiled.extend(idx.iter().map(|&i| rays[i])));
        *rays = tiled;
    }

    /// The rays of frame 0 for a scene box.
    #[must_use]
    pub fn rays(self, bounds: &Aabb) -> Vec<Ray> {
        match self {
            RaySpec::Lidar(n) => {
                let mut out = Vec::new();
                crate::report::rays::lidar_rays(bounds, n, 0, &mut out);
                out
            }
            RaySpec::Size(..) | RaySpec::Count(_) => {
                let (w, h) = self.image_size().unwrap_or((1, 1));
                let mut r = camera_rays(bounds, w, h);
                if let RaySpec::Count(n) = self {
                    r.truncate(n.max(1));
                }
                r
            }
        }
    }

    /// The camera image's width and height (a `Count`'s square image, cut to the count in
    /// [`RaySpec::rays`]); `None` for the lidar's fan.
    fn image_size(self) -> Option<(usize, usize)> {
        match self {
            RaySpec::Size(w, h) => Some((w, h)),
            RaySpec::Count(n) => {
                let w = (n as f64).sqrt().ceil().max(1.0) as usize;
                Some((w, n.div_ceil(w).max(1)))
            }
            RaySpec::Lidar(_) => None,
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
    /// With the oracle, also the one whose moves include the policies' rungs (costs
    /// `frames^2 / 2` builds and `frames^3 / 6` refits and replays per rung).
    pub oracle_rungs: bool,
    /// Also run the default mesh policy under each top-level tree policy (refit, rebuild, the
    /// configured one) and report what the top-level tree costs.
    pub tlas_compare: bool,
    /// Which mesh trees the rays walk.
    pub traversal: Traversal,
    /// Trace the frame's rays as packets ([`Engine::closest_hit_packets`]; a camera image in
    /// tiles), the ray-work sample taken from them after the pass.
    pub packets: bool,
    /// What the policies decide on.
    pub cost: CostMeasure,
    /// Unit prices of the modelled measure (every engine decides with them: the schedules do
    /// not depend on the machine's load).
    pub prices: Prices,
    /// Rays per frame the modelled measure counts (every `k`-th, `k` the least stride that
    /// keeps at most this many; all rays when the frame casts fewer): the judge's sample,
    /// denser than the engine's own, replayed on every run's trees and on the oracle's.
    pub judge_rays: usize,
    /// Tell each engine how many frames the run makes ([`Engine::plan_frames`]), so that the
    /// policies leave out actions that cannot pay for themselves before its end; false: every
    /// run is open-ended.
    pub known_length: bool,
    /// The background rebuild's worker's scheduling class.
    pub worker: WorkerPriority,
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
            oracle_rungs: false,
            tlas_compare: true,
            traversal: Traversal::DEFAULT,
            packets: false,
            cost: CostMeasure::default(),
            prices: Prices::default(),
            judge_rays: 16384,
            known_length: true,
            worker: WorkerPriority::Normal,
        }
    }
}

/// One frame of one policy.
#[derive(Clone, Debug, Serialize)]
pub struct FrameRow {
    /// Policy name.
    pub policy: String,
    /// Frame number (frame 0 is the animation's start; the engines are built at the run's
    /// first frame, which has no row).
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
    /// Modelled mesh updates, ms.
    pub model_update_ms: f64,
    /// Modelled trace cost: the work of the bench's sample of the frame's rays on this run's
    /// trees, scaled to all rays, ms.
    pub model_trace_ms: f64,
    /// The engine's own estimate of it (its one-in-64 sample), ms.
    pub est_trace_ms: f64,
    /// Modelled cost of tracing the sample again, ms.
    pub model_sample_ms: f64,
    /// Half width of the 95% confidence interval of the sample's mean work per ray, as a share
    /// of the mean.
    pub work_ci95_rel: f64,
    /// Largest estimated ray-work degradation of a mesh (0 under the SAH measure).
    pub est_work_ratio: f32,
    /// Largest ray-work ratio measured at a rebuild (replaced tree over new, same rays; 0
    /// without).
    pub measured_work_ratio: f32,
    /// Largest true ray-work degradation of a mesh: its tree's modelled trace cost over a fresh
    /// tree's on the frame's sampled rays (the all-pairs pass; 0 without the oracle).
    pub work_ratio: f32,
    /// CPU time of the process over the frame's update and (fastest) trace, ms.
    pub cpu_ms: f64,
    /// Time the threads waited for a core meanwhile, ms.
    pub wait_ms: f64,
    /// Wall-clock time of sampling the rays again with counters, ms.
    pub sample_ms: f64,
    /// Wall-clock time of the frame's first trace pass, the one right after the update (as a
    /// frame loop traces once a frame) and the one the sample is taken in, ms.
    pub first_pass_ms: f64,
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
    /// Modelled total (mesh updates, tracing, and the ray sample for the policies that read
    /// it), ms: the same on every run with the same prices.
    pub modelled_ms: f64,
    /// `modelled_ms` over the modelled oracle's total (0 without the oracle).
    pub oracle_ratio_modelled: f64,
    /// `modelled_ms` over the total of the modelled oracle whose moves include the rungs (0
    /// when it was not computed: only with [`Options::oracle_rungs`] and a policy with rungs).
    pub oracle_rungs_ratio_modelled: f64,
    /// Wall clock of the updates and traces (`total_ms`), ms.
    pub wall_ms: f64,
    /// CPU time of the process's threads over the same, ms.
    pub cpu_ms: f64,
    /// Time the threads were runnable but waited for a core, ms.
    pub wait_ms: f64,
    /// True when `wait_ms` exceeds [`BUSY_SHARE`] of `cpu_ms`: the machine was busy and the
    /// wall-clock figures are disturbed.
    pub busy: bool,
    /// Frames some mesh was rebuilt at (numbered as [`FrameRow::frame`]).
    pub rebuild_frames: Vec<usize>,
    /// Wall-clock time of sampling over the time of the trace passes it was taken in, less it:
    /// each frame's first pass, right after the update, as a frame loop traces (the fastest
    /// of the frame's passes, which `trace_ms` counts, runs with warm caches).
    pub sample_share: f64,
    /// Modelled cost of sampling over the modelled trace cost (0 for the policies that do not
    /// read the sample).
    pub sample_share_modelled: f64,
    /// Median, 95th percentile and largest frame time (update plus trace, wall clock), ms.
    pub p50_ms: f64,
    /// 95th percentile frame time, ms.
    pub p95_ms: f64,
    /// Largest frame time, ms.
    pub max_ms: f64,
    /// What the policy's engine held after the last frame ([`Engine::memory`]).
    pub memory: EngineMemory,
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

/// The best schedule in the modelled measure.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ModelledOracle {
    /// Modelled total of the best schedule (fixed trace cost plus each deforming mesh's best),
    /// ms.
    pub total_ms: f64,
    /// Rebuilds over all meshes.
    pub rebuilds: usize,
    /// For each deforming mesh, the frames it is rebuilt at.
    pub rebuild_frames: Vec<Vec<usize>>,
    /// For each deforming mesh, the frames it goes back to the tree its last rebuild replaced.
    pub back_frames: Vec<Vec<usize>>,
    /// Modelled totals of always refitting and always rebuilding (no sampling overhead), ms.
    pub refit_ms: f64,
    /// See `refit_ms`.
    pub rebuild_ms: f64,
    /// What the oracle's moves are and what it is not charged for.
    pub moves: String,
    /// The oracle whose moves also include the rungs the policies run (computed only with
    /// [`Options::oracle_rungs`] and a policy with rungs; 0 otherwise): modelled total, ms.
    pub rungs_total_ms: f64,
    /// Those rungs, by name.
    pub rungs: Vec<String>,
    /// For each deforming mesh, that oracle's frames other than refits: `(frame, action)`.
    pub rung_schedule: Vec<Vec<(usize, String)>>,
    /// What that oracle's moves are.
    pub rungs_moves: String,
}

/// How well each measure of degradation follows the trace time: per frame, the always-refit
/// tree against the always-rebuilt (fresh) one.
#[derive(Clone, Debug, Default, Serialize)]
pub struct DegradationCheck {
    /// Frames compared.
    pub frames: usize,
    /// Mean over the frames of the measured (wall clock) trace-time ratio, refit over rebuild.
    pub time_ratio: f64,
    /// Mean of the ray-work ratio (the refitted tree's modelled trace cost over the fresh
    /// tree's, same sampled rays).
    pub work_ratio: f64,
    /// Mean of the SAH ratio (the refitted tree's SAH over the fresh tree's).
    pub sah_ratio: f64,
    /// `work_ratio / time_ratio - 1`.
    pub work_error: f64,
    /// `sah_ratio / time_ratio - 1`.
    pub sah_error: f64,
    /// Mean of the engine's estimated ray-work degradation under the default policy (which
    /// rebuilds, so not the same trees: for reference).
    pub est_work_ratio_default: f64,
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
    /// Engines run in lockstep, a frame of each in turn (the policies asked, the oracle's
    /// always-refit and always-rebuild, the top-level tree comparison's).
    pub lockstep: usize,
    /// Whether the frames' rays were traced as packets (`--packets`).
    pub packets: bool,
    /// The scheduling class of `async`'s background worker.
    pub worker_priority: WorkerPriority,
    /// What the policies decided on.
    pub cost: CostMeasure,
    /// Unit prices of the modelled measure.
    pub prices: Prices,
    /// Per policy, in the order asked.
    pub policies: Vec<PolicySummary>,
    /// The oracle in the wall-clock measure (measured updates, SAH trace model).
    pub oracle: OracleSummary,
    /// The oracle in the modelled measure.
    pub oracle_modelled: ModelledOracle,
    /// Policies whose modelled total fell below the modelled oracle's (a bug if not empty).
    pub below_oracle: Vec<String>,
    /// True when some run's threads waited for a core more than [`BUSY_SHARE`] of their CPU
    /// time: the wall-clock columns are disturbed.
    pub busy: bool,
    /// Ray work and SAH against the measured trace time.
    pub degradation: DegradationCheck,
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
    /// `[frame][mesh]`: the frame the mesh's tree was last built at.
    built: Vec<Vec<usize>>,
    /// `[frame][mesh]`: what the mesh's update did.
    actions: Vec<Vec<Action>>,
    /// Per frame: top-level tree rebuilt, its SAH ratio.
    tlas: Vec<(bool, f32)>,
    /// What the engine held after the last frame.
    memory: EngineMemory,
}

/// Runs every configuration over every frame in lockstep: each frame is posed into every engine
/// and updated, then the engines trace the frame's rays in turn, `trace_repeats` rounds in a
/// rotating order, each keeping its fastest pass, and sample them for the ray-work measure.
/// Interleaving puts every configuration under the same load (this machine is shared), so
/// differences between their times are the trees'. With `sampled`, the first engine's sample
/// of each frame is kept there (every engine's entries are the same).
fn run_lockstep(
    src: &mut dyn FrameSource,
    configs: &[EngineConfig],
    bounds: &Aabb,
    opts: &Options,
    frames: usize,
    mut sampled: Option<&mut Vec<SampledFrame>>,
) -> Vec<Run> {
    let deforming = src.deforming().to_vec();
    let mut engines: Vec<Engine> = configs.iter().map(|&c| src.build(0, c)).collect();
    if opts.known_length {
        for e in &mut engines {
            e.plan_frames(Some(frames as u64));
        }
    }
    let mut frame_rays = Vec::new();
    opts.rays.frame_rays(bounds, 0, &mut frame_rays);
    if opts.packets {
        // The camera's rays stay the same every frame: in tiles once.
        opts.rays.in_tiles(&mut frame_rays);
    }
    let mut hits: Vec<Option<SceneHit>> = vec![None; frame_rays.len()];
    let step = (frame_rays.len() / opts.counted_rays.max(1)).max(1);
    let mut runs: Vec<Run> = configs
        .iter()
        .map(|&config| Run {
            config,
            rows: Vec::with_capacity(frames),
            refit: vec![vec![0.0; deforming.len()]; frames + 1],
            rebuild: vec![vec![0.0; deforming.len()]; frames + 1],
            share: vec![vec![0.0; deforming.len()]; frames + 1],
            sah: vec![vec![0.0; deforming.len()]; frames + 1],
            built: vec![vec![0; deforming.len()]; frames + 1],
            actions: vec![vec![Action::None; deforming.len()]; frames + 1],
            tlas: Vec::with_capacity(frames),
            memory: EngineMemory::default(),
        })
        .collect();
    if let Some(s) = sampled.as_deref_mut() {
        s.clear();
        s.push(SampledFrame::default());
    }
    // Warm-up: one untimed pass each over frame 0, sampled as a frame loop's first trace is
    // (the ray-work measure's reference: the fresh trees' work per entry).
    for e in &mut engines {
        trace_pass(e, &frame_rays, &mut hits, opts.packets, true);
    }
    let n = engines.len();
    let mut best = vec![f64::INFINITY; n];
    let mut first = vec![0.0; n];
    let mut best_clock = vec![Elapsed::default(); n];
    let mut update_clock = vec![Elapsed::default(); n];
    for f in 1..=frames {
        opts.rays.frame_rays(bounds, f, &mut frame_rays);
        hits.resize(frame_rays.len(), None);
        let rays = frame_rays.as_slice();
        for (e, u) in engines.iter_mut().zip(&mut update_clock) {
            let c = CpuClock::now();
            src.advance(e, f);
            e.update();
            *u = c.elapsed_ms();
        }
        best.fill(f64::INFINITY);
        for rep in 0..opts.trace_repeats.max(1) {
            for k in 0..n {
                let i = (k + rep + f) % n;
                let c = CpuClock::now();
                // The first pass takes the engine's sample, as a frame loop's trace does.
                trace_pass(&mut engines[i], rays, &mut hits, opts.packets, rep == 0);
                let t = c.elapsed_ms();
                if rep == 0 {
                    first[i] = t.wall_ms;
                }
                if t.wall_ms < best[i] {
                    best[i] = t.wall_ms;
                    best_clock[i] = t;
                }
            }
        }
        let judge = judge_sample(&engines[0], rays, opts, f, &deforming);
        for (i, (e, run)) in engines.iter_mut().zip(&mut runs).enumerate() {
            e.record_trace(best[i], rays.len() as u64);
            let mut clock = update_clock[i];
            clock += best_clock[i];
            record_frame(e, &deforming, run, rays, step, f, clock);
            if let Some(row) = run.rows.last_mut() {
                row.first_pass_ms = first[i];
                row.model_trace_ms = judged_trace_ms(e, &judge, &deforming, &opts.prices);
            }
        }
        if let Some(s) = sampled.as_deref_mut() {
            s.push(judge);
        }
    }
    for (e, run) in engines.iter().zip(&mut runs) {
        run.memory = e.memory();
    }
    runs
}

/// One trace pass of the frame's rays: ray by ray or as packets, the engine's ray-work sample
/// taken when `sampled` (in the pass's own traversal ray by ray; after the packets, from the
/// same rays walked one by one).
fn trace_pass(
    e: &mut Engine,
    rays: &[Ray],
    hits: &mut [Option<SceneHit>],
    packets: bool,
    sampled: bool,
) {
    match (packets, sampled) {
        (false, true) => {
            e.closest_hit_batch_sampled(rays, hits);
        }
        (false, false) => e.closest_hit_batch(rays, hits),
        (true, _) => {
            e.closest_hit_packets(rays, hits);
            if sampled {
                e.sample_rays(rays, Query::Closest);
            }
        }
    }
}

/// The bench's sample of frame `f`'s rays, traced on engine `e`: what every run shares of it
/// (the entries into instances, and the work no schedule changes).
fn judge_sample(
    e: &Engine,
    rays: &[Ray],
    opts: &Options,
    f: usize,
    deforming: &[MeshId],
) -> SampledFrame {
    let stride = rays.len().div_ceil(opts.judge_rays.max(1)).max(1);
    // An offset that moves with the frame (Knuth's multiplicative hash).
    let offset = (f as u64).wrapping_mul(2_654_435_761) as usize % stride;
    let mut entries = Vec::new();
    let (mut fixed, per_mesh) = e.trace_sampled(rays, Query::Closest, stride, offset, &mut entries);
    for (m, w) in per_mesh.iter().enumerate() {
        if !deforming.contains(&MeshId(m as u32)) {
            fixed += *w;
        }
    }
    let scale = stride as f64;
    SampledFrame {
        entries,
        fixed_ms: scale * opts.prices.trace_ms(fixed),
        scale,
    }
}

/// Modelled trace cost of engine `e`'s trees on the bench's sample `judge`, ms.
fn judged_trace_ms(e: &Engine, judge: &SampledFrame, deforming: &[MeshId], prices: &Prices) -> f64 {
    judge.fixed_ms
        + deforming
            .iter()
            .map(|m| judge.replay_ms(e, *m, prices))
            .sum::<f64>()
}

/// Appends frame `f` of engine `e` (updated, traced and sampled) to `run`.
fn record_frame(
    e: &Engine,
    deforming: &[MeshId],
    run: &mut Run,
    rays: &[Ray],
    step: usize,
    f: usize,
    clock: Elapsed,
) {
    let s = *e.frame_stats();
    let mut n = 0u64;
    let mut in_box = 0u64;
    let root = e.bounds();
    for r in rays.iter().step_by(step) {
        n += 1;
        if r.hit_box(root.min, root.max, r.tmax).is_some() {
            in_box += 1;
        }
    }
    let (pn, pt) = e.predicted_work();
    let p_hit = in_box as f64 / n.max(1) as f64;
    let (mut est_work, mut measured_work) = (0.0f32, 0.0f32);
    for (k, m) in deforming.iter().enumerate() {
        let ms = e.mesh_stats(*m);
        run.refit[f][k] = ms.refit_ms;
        run.rebuild[f][k] = ms.rebuild_ms;
        run.share[f][k] = e.mesh_trace_share(*m);
        run.sah[f][k] = ms.sah;
        run.actions[f][k] = ms.action;
        run.built[f][k] = if ms.action == Action::Rebuild {
            f
        } else {
            run.built[f - 1][k]
        };
        est_work = est_work.max(ms.work_ratio);
        measured_work = measured_work.max(ms.measured_work_ratio);
    }
    let work = e.work_estimate();
    let sampled = work.sampled.max(1) as f64;
    let counted = e.sampled_work();
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
        nodes_per_ray: counted.nodes as f64 / sampled,
        tris_per_ray: counted.prims as f64 / sampled,
        predicted_nodes_per_ray: pn * p_hit,
        predicted_tris_per_ray: pt * p_hit,
        model_update_ms: s.model_update_ms,
        model_trace_ms: s.model_trace_ms,
        est_trace_ms: s.model_trace_ms,
        model_sample_ms: s.model_sample_ms,
        work_ci95_rel: if work.mean > 0.0 {
            work.ci95 / work.mean
        } else {
            0.0
        },
        est_work_ratio: est_work,
        measured_work_ratio: measured_work,
        work_ratio: 0.0,
        cpu_ms: clock.cpu_ms,
        wait_ms: clock.wait_ms,
        sample_ms: s.sample_ms,
        first_pass_ms: 0.0,
    });
}

fn summarize(policy: Policy, rows: &[FrameRow], oracle_total: f64) -> PolicySummary {
    let n = rows.len().max(1) as f64;
    let update: f64 = rows.iter().map(|r| r.update_ms).sum();
    let trace: f64 = rows.iter().map(|r| r.trace_ms).sum();
    let rays: u64 = rows.iter().map(|r| r.rays).sum();
    let total = update + trace;
    let modelled: f64 = rows
        .iter()
        .map(|r| {
            // Only the policies that read the ray sample are charged for it (the bench has
            // every run take one, for its statistics).
            r.model_update_ms
                + r.model_trace_ms
                + if PolicyState::reads_sample(policy) {
                    r.model_sample_ms
                } else {
                    0.0
                }
        })
        .sum();
    let cpu: f64 = rows.iter().map(|r| r.cpu_ms).sum();
    let wait: f64 = rows.iter().map(|r| r.wait_ms).sum();
    let sample: f64 = rows.iter().map(|r| r.sample_ms).sum();
    let first_pass: f64 = rows.iter().map(|r| r.first_pass_ms).sum();
    let mut frame_ms: Vec<f64> = rows.iter().map(|r| r.update_ms + r.trace_ms).collect();
    frame_ms.sort_by(f64::total_cmp);
    let pct = |q: f64| -> f64 {
        if frame_ms.is_empty() {
            0.0
        } else {
            frame_ms[((frame_ms.len() - 1) as f64 * q).round() as usize]
        }
    };
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
        modelled_ms: modelled,
        oracle_ratio_modelled: 0.0,
        oracle_rungs_ratio_modelled: 0.0,
        wall_ms: total,
        cpu_ms: cpu,
        wait_ms: wait,
        busy: wait > BUSY_SHARE * cpu,
        rebuild_frames: rows
            .iter()
            .filter(|r| r.rebuilds > 0)
            .map(|r| r.frame)
            .collect(),
        sample_share: if first_pass > sample {
            sample / (first_pass - sample)
        } else {
            0.0
        },
        sample_share_modelled: {
            let t: f64 = rows.iter().map(|r| r.model_trace_ms).sum();
            let s: f64 = rows.iter().map(|r| r.model_sample_ms).sum();
            if t > 0.0 && PolicyState::reads_sample(policy) {
                s / t
            } else {
                0.0
            }
        },
        p50_ms: pct(0.5),
        p95_ms: pct(0.95),
        max_ms: frame_ms.last().copied().unwrap_or(0.0),
        memory: EngineMemory::default(),
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
        cost: opts.cost,
        prices: opts.prices,
        timing: Timing::Priced,
        worker: opts.worker,
        // Every run keeps its sample: the always-rebuild run's shares of the trace weigh the
        // degradation check and the wall-clock oracle, and every run's wall clock includes it.
        always_sample: true,
    };
    // The first frame's box, less far outliers: what the camera and the lidar look at.
    let (bounds, _) = src.build(0, config(Policy::Refit)).view_bounds();
    let rays_per_frame = opts.rays.rays(&bounds).len();
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
    let mut sampled = Vec::new();
    let mut all_runs = run_lockstep(src, &configs, &bounds, opts, frames, Some(&mut sampled));

    let mut oracle = OracleSummary::default();
    let mut modelled = ModelledOracle::default();
    let mut degradation = DegradationCheck::default();
    let mut oracle_total = 0.0;
    if opts.oracle && frames > 0 {
        progress("oracle: building at every frame, refitting through the later ones");
        let pairs = all_pairs::measure(src, config(Policy::Refit), &sampled, &opts.prices, frames);
        let runs = &all_runs[..wanted.len()];
        let find = |p: Policy| &runs[wanted.iter().position(|&q| q == p).expect("run")];
        let (refit_run, rebuild_run) = (find(Policy::Refit), find(Policy::Rebuild));
        oracle_total = wall_clock_oracle(&mut oracle, &pairs.sah, refit_run, rebuild_run, runs);
        modelled = modelled_oracle(&pairs.work, &sampled);
        let rungs = if opts.oracle_rungs {
            oracle_rungs(&wanted)
        } else {
            Vec::new()
        };
        if !rungs.is_empty() {
            progress("oracle over the rungs: restructuring every tree at every later frame");
            let rc = all_pairs::measure_rungs(
                src,
                config(Policy::Refit),
                &sampled,
                &opts.prices,
                frames,
                &rungs,
            );
            add_rungs(&mut modelled, &pairs.work, &rc, &rungs, &sampled);
        }
        degradation = degradation_check(&pairs, refit_run, rebuild_run);
        // The true fresh ratio and ray-work ratio of every run's trees (same positions, same
        // deterministic build).
        for run in all_runs.iter_mut() {
            for (f, row) in (1..=frames).zip(run.rows.iter_mut()) {
                row.fresh_ratio = pairs
                    .sah
                    .iter()
                    .zip(&run.sah[f])
                    .map(|(t, &s)| if t[f][0] > 0.0 { s / t[f][0] } else { 1.0 })
                    .fold(1.0, f32::max);
                row.work_ratio = pairs
                    .work
                    .iter()
                    .zip(&run.built[f])
                    .map(|(w, &b)| w.ratio(b, f) as f32)
                    .fold(1.0, f32::max);
            }
        }
        let policy_runs = &all_runs[..wanted.len()];
        if let Some(r) = policy_runs
            .iter()
            .find(|r| r.config.policy == Policy::DEFAULT)
        {
            degradation.est_work_ratio_default = r
                .rows
                .iter()
                .map(|x| f64::from(x.est_work_ratio))
                .sum::<f64>()
                / r.rows.len().max(1) as f64;
        }
    }
    let runs = &all_runs[..wanted.len()];

    let mut policies = Vec::new();
    let mut per_frame = Vec::new();
    let mut speed = Vec::new();
    let mut below_oracle = Vec::new();
    for (p, r) in wanted.iter().zip(runs) {
        if !opts.policies.contains(p) {
            continue;
        }
        let mut s = summarize(*p, &r.rows, oracle_total);
        s.memory = r.memory;
        if modelled.total_ms > 0.0 {
            s.oracle_ratio_modelled = s.modelled_ms / modelled.total_ms;
            // The oracle schedules refits and rebuilds only: a policy with other actions may
            // beat it.
            if s.modelled_ms < modelled.total_ms * (1.0 - 1e-9) && !p.beyond_oracle() {
                below_oracle.push(format!(
                    "{}: modelled {:.6} ms below the oracle's {:.6} ms",
                    s.policy, s.modelled_ms, modelled.total_ms
                ));
            }
        }
        if modelled.rungs_total_ms > 0.0 {
            s.oracle_rungs_ratio_modelled = s.modelled_ms / modelled.rungs_total_ms;
            if s.modelled_ms < modelled.rungs_total_ms * (1.0 - 1e-9) && within_rung_moves(*p, r) {
                below_oracle.push(format!(
                    "{}: modelled {:.6} ms below the rung oracle's {:.6} ms",
                    s.policy, s.modelled_ms, modelled.rungs_total_ms
                ));
            }
        }
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
                ..config(Policy::Rebuild)
            };
            let r = run_lockstep(src, &[cfg], &bounds, opts, bf, None).remove(0);
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
    let busy = all_runs.iter().any(|r| {
        let cpu: f64 = r.rows.iter().map(|x| x.cpu_ms).sum();
        let wait: f64 = r.rows.iter().map(|x| x.wait_ms).sum();
        wait > BUSY_SHARE * cpu
    });
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
    let mut report = Report {
        source: src.name(),
        triangles: src.triangle_count(),
        deforming_meshes: deforming,
        frames,
        rays_per_frame,
        threads: rayon::current_num_threads(),
        lockstep: configs.len(),
        packets: opts.packets,
        worker_priority: opts.worker,
        cost: opts.cost,
        prices: opts.prices,
        policies,
        oracle,
        oracle_modelled: modelled,
        below_oracle,
        busy,
        degradation,
        tlas,
        speed,
        per_frame,
    };
    number_frames(&mut report, src.first_frame());
    report
}

/// Gives the report's frames the source's numbers (the run counts from 0, the frame it was
/// built at; a [`crate::engine::source::Window`] starts further on).
fn number_frames(r: &mut Report, first: usize) {
    if first == 0 {
        return;
    }
    for row in &mut r.per_frame {
        row.frame += first;
    }
    let frame_lists = r
        .policies
        .iter_mut()
        .map(|p| &mut p.rebuild_frames)
        .chain(r.oracle.rebuild_frames.iter_mut())
        .chain(r.oracle_modelled.rebuild_frames.iter_mut())
        .chain(r.oracle_modelled.back_frames.iter_mut());
    for list in frame_lists {
        for f in list {
            *f += first;
        }
    }
}

/// The modelled oracle: the fixed trace cost plus each deforming mesh's exact best schedule.
fn modelled_oracle(
    work: &[crate::engine::oracle::WorkCosts],
    sampled: &[SampledFrame],
) -> ModelledOracle {
    use crate::engine::oracle::{BACK_MAX_FRAMES, BackMove};
    let fixed: f64 = sampled.iter().skip(1).map(|s| s.fixed_ms).sum();
    let mut o = ModelledOracle {
        total_ms: fixed,
        refit_ms: fixed,
        rebuild_ms: fixed,
        moves: format!(
            "per deforming mesh and frame: refit the tree in use, rebuild it, or go back to the \
            tree the last rebuild replaced, refitted (the engine's moves under the ray-work \
            measure); charged for refits, rebuilds and tracing at the same prices as the \
            policies, not for the ray sample, estimates or the comparisons that decide going \
            back, which it does not need; over more than {BACK_MAX_FRAMES} frames it does not \
            go back"
        ),
        ..ModelledOracle::default()
    };
    for w in work {
        let s = w.best_going_back();
        let n = w.frames() + 1;
        o.total_ms += s.cost_ms;
        o.refit_ms += w.cost_of(&vec![false; n]);
        o.rebuild_ms += w.cost_of(&vec![true; n]);
        let rebuilt = s.frames_with(BackMove::Rebuild);
        o.rebuilds += rebuilt.len();
        o.rebuild_frames.push(rebuilt);
        o.back_frames.push(s.frames_with(BackMove::Back));
    }
    o
}

/// The rungs the rung oracle offers: those of the policies run (the ladder's budgets for
/// `ladder`), each once.
fn oracle_rungs(policies: &[Policy]) -> Vec<Decision> {
    let mut rungs = Vec::new();
    for p in policies {
        let wanted: &[Decision] = match p {
            Policy::Optimize(b) => &[Decision::Optimize(*b)],
            Policy::Partial(b) => &[Decision::Partial(*b)],
            Policy::Ladder => &[
                Decision::Optimize(LADDER_OPTIMIZE),
                Decision::Partial(LADDER_PARTIAL),
            ],
            _ => &[],
        };
        for d in wanted {
            if !rungs.contains(d) {
                rungs.push(*d);
            }
        }
    }
    rungs
}

/// The name of a rung: that of the policy that takes it alone.
fn rung_name(d: Decision) -> String {
    match d {
        Decision::Optimize(b) => Policy::Optimize(b).to_string(),
        Decision::Partial(b) => Policy::Partial(b).to_string(),
        _ => format!("{d:?}"),
    }
}

/// Adds the oracle over the rungs to `o`.
fn add_rungs(
    o: &mut ModelledOracle,
    work: &[crate::engine::oracle::WorkCosts],
    rung_costs: &[Vec<crate::engine::oracle::RungCosts>],
    rungs: &[Decision],
    sampled: &[SampledFrame],
) {
    use crate::engine::oracle::Move;
    o.rungs = rungs.iter().map(|&d| rung_name(d)).collect();
    o.rungs_total_ms = sampled.iter().skip(1).map(|s| s.fixed_ms).sum();
    for (w, rc) in work.iter().zip(rung_costs) {
        let s = w.best_with_rungs(rc);
        o.rungs_total_ms += s.cost_ms;
        o.rung_schedule.push(
            s.moves
                .iter()
                .enumerate()
                .skip(1)
                .filter_map(|(f, m)| match m {
                    Move::Refit => None,
                    Move::Rebuild => Some((f, "rebuild".to_string())),
                    Move::Rung(k) => Some((f, o.rungs[*k].clone())),
                })
                .collect(),
        );
    }
    o.rungs_moves = format!(
        "per deforming mesh and frame: refit, rebuild, or refit then one of the rungs {}, \
        with at most one rung between two rebuilds (a policy that restructures again before \
        rebuilding makes moves outside these and may come out below); charged as the oracle \
        above",
        o.rungs.join(", ")
    );
}

/// True when run `r` of policy `p` made only the rung oracle's moves: no rungs, or at most
/// one rung on each mesh between two rebuilds (and no background rebuild).
fn within_rung_moves(p: Policy, r: &Run) -> bool {
    if p == Policy::Async {
        return false;
    }
    let meshes = r.actions.first().map_or(0, Vec::len);
    (0..meshes).all(|k| {
        let mut restructured = false;
        r.actions.iter().all(|a| match a[k] {
            Action::Rebuild => {
                restructured = false;
                true
            }
            Action::Optimize | Action::Partial => !std::mem::replace(&mut restructured, true),
            // The rung oracle does not go back to an earlier tree.
            Action::AsyncStart | Action::AsyncSwap | Action::Back => false,
            Action::None | Action::Refit => true,
        })
    })
}

/// Per frame, the refitted tree against the fresh one: measured trace-time ratio (always-refit
/// run over always-rebuild run), ray-work ratio and SAH ratio.
fn degradation_check(pairs: &all_pairs::AllPairs, refit: &Run, rebuild: &Run) -> DegradationCheck {
    let frames = refit.rows.len();
    let mut c = DegradationCheck {
        frames,
        ..DegradationCheck::default()
    };
    if frames == 0 || pairs.work.is_empty() {
        return c;
    }
    for f in 1..=frames {
        let (rt, bt) = (refit.rows[f - 1].trace_ms, rebuild.rows[f - 1].trace_ms);
        c.time_ratio += if bt > 0.0 { rt / bt } else { 1.0 };
        // The whole frame's modelled trace: both runs' own samples.
        let (rw, bw) = (
            refit.rows[f - 1].model_trace_ms,
            rebuild.rows[f - 1].model_trace_ms,
        );
        c.work_ratio += if bw > 0.0 { rw / bw } else { 1.0 };
        let (mut sr, mut sb) = (0.0f64, 0.0f64);
        for (k, sah) in pairs.sah.iter().enumerate() {
            let share = rebuild.share[f][k];
            sr += share * f64::from(sah[0][f]);
            sb += share * f64::from(sah[f][0]);
        }
        c.sah_ratio += if sb > 0.0 { sr / sb } else { 1.0 };
    }
    let n = frames as f64;
    c.time_ratio /= n;
    c.work_ratio /= n;
    c.sah_ratio /= n;
    c.work_error = c.work_ratio / c.time_ratio - 1.0;
    c.sah_error = c.sah_ratio / c.time_ratio - 1.0;
    c
}

/// The wall-clock oracle (measured refit and rebuild times, the SAH trace model calibrated on
/// the always-refit run); returns its total.
fn wall_clock_oracle(
    oracle: &mut OracleSummary,
    sah: &[Vec<Vec<f32>>],
    refit_run: &Run,
    rebuild_run: &Run,
    runs: &[Run],
) -> f64 {
    let frames = refit_run.rows.len();
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
    let mut scene = SceneCosts {
        fixed_ms: fixed,
        meshes: Vec::with_capacity(sah.len()),
    };
    for (k, sah) in sah.iter().enumerate() {
        scene.meshes.push(MeshCosts {
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
            sah: sah.clone(),
        });
    }
    let measured = |r: &Run| r.rows.iter().map(|x| x.update_ms + x.trace_ms).sum::<f64>();
    oracle.measured_refit_ms = measured(refit_run);
    oracle.measured_rebuild_ms = measured(rebuild_run);
    let cal = scene.calibrate(oracle.measured_refit_ms);
    let (total, schedules) = scene.best(cal.alpha);
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
    total
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

/// The modelled measure's table: per policy its modelled total and ratio to the modelled
/// oracle, next to its wall clock, CPU time and frame-time percentiles.
fn modelled_table(r: &Report) -> String {
    let p = &r.prices;
    let mut s = format!(
        "modelled (policies decide on {}; prices: refit {:.2} ns/tri, rebuild {:.2} ns/(n log2 n), \
         estimate {:.2} ns/tri, trace {:.2} ns/node + {:.2} ns/tri; pose and top-level tree \
         updates left out, the same for every policy):\n",
        r.cost,
        p.refit_ns_per_tri,
        p.rebuild_ns_per_tri_log,
        p.estimate_ns_per_tri,
        p.trace_ns_per_node,
        p.trace_ns_per_tri
    );
    s.push_str(&format!(
        "{:<16} {:>12} {:>8} {:>8} {:>10} {:>10} {:>5} {:>9} {:>8} {:>8} {:>8}\n",
        "policy",
        "modelled ms",
        "/oracle",
        "rebuilds",
        "wall ms",
        "cpu ms",
        "busy",
        "wall/orc",
        "p50 ms",
        "p95 ms",
        "max ms"
    ));
    for q in &r.policies {
        s.push_str(&format!(
            "{:<16} {:>12.3} {:>8} {:>8} {:>10.2} {:>10.2} {:>5} {:>9} {:>8.3} {:>8.3} {:>8.3}\n",
            format!("{}{}", q.policy, if q.default { "*" } else { "" }),
            q.modelled_ms,
            super::nonzero_or_dash(q.oracle_ratio_modelled, 4),
            q.rebuilds,
            q.wall_ms,
            q.cpu_ms,
            if q.busy { "BUSY" } else { "no" },
            if q.busy {
                "(busy)".to_string()
            } else {
                super::nonzero_or_dash(q.oracle_ratio, 3)
            },
            q.p50_ms,
            q.p95_ms,
            q.max_ms
        ));
    }
    let o = &r.oracle_modelled;
    if o.total_ms > 0.0 {
        s.push_str(&format!(
            "{:<16} {:>12.3} {:>8} {:>8}   (always-refit {:.3}, always-rebuild {:.3}, no sampling)\n",
            "oracle", o.total_ms, "1", o.rebuilds, o.refit_ms, o.rebuild_ms
        ));
        if o.rungs_total_ms > 0.0 {
            s.push_str(&format!(
                "{:<16} {:>12.3}   (moves also {}, at most one between rebuilds); over it: {}\n",
                "oracle+rungs",
                o.rungs_total_ms,
                o.rungs.join(", "),
                r.policies
                    .iter()
                    .map(|q| format!("{} {:.4}", q.policy, q.oracle_rungs_ratio_modelled))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        let d = &r.degradation;
        s.push_str(&format!(
            "refitted against fresh trees, mean over {} frames: trace time {:.3}x, ray work \
             {:.3}x ({:+.1}%), SAH {:.3}x ({:+.1}%)\n",
            d.frames,
            d.time_ratio,
            d.work_ratio,
            100.0 * d.work_error,
            d.sah_ratio,
            100.0 * d.sah_error
        ));
    }
    let share: Vec<f64> = r.policies.iter().map(|q| q.sample_share).collect();
    let modelled = r
        .policies
        .iter()
        .map(|q| q.sample_share_modelled)
        .fold(0.0, f64::max);
    if !share.is_empty() {
        // Over the sampled frames only (an unsampled frame has no interval).
        let mean_ci = mean(
            r.per_frame
                .iter()
                .map(|x| x.work_ci95_rel)
                .filter(|&c| c > 0.0),
        );
        // The default policy samples only the frames on which it could act (`engine::watch`).
        let default = r.policies.iter().find(|q| q.default).map(|q| &q.policy);
        let frames = r.per_frame.iter().filter(|x| Some(&x.policy) == default);
        let (sampled, all) = frames.fold((0, 0), |(k, n), x| {
            (k + usize::from(x.model_sample_ms > 0.0), n + 1)
        });
        s.push_str(&format!(
            "ray sample: 1 ray in {SAMPLE_STRIDE}, at most {SAMPLE_MAX} a frame, taken in the \
             trace's own pass (the default \
             policy's on {sampled} of {all} frames): {:.2}% of the wall-clock time of the passes \
             it was taken in, the frames' first (largest over the policies; {:.2}% modelled); \
             mean work per ray known to +-{:.1}% (95%)\n",
            100.0 * share.iter().copied().fold(0.0, f64::max),
            100.0 * modelled,
            100.0 * mean_ci
        ));
    }
    for b in &r.below_oracle {
        s.push_str(&format!("BELOW THE ORACLE: {b}\n"));
    }
    s
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    if n > 0 { sum / n as f64 } else { 0.0 }
}

/// The summary table, one line per policy and one for the oracle.
#[must_use]
pub fn summary_table(r: &Report) -> String {
    let mut s = format!(
        "{}: {} triangles, {} deforming mesh(es), {} frames, {} rays/frame{}, {} thread(s)\n",
        r.source,
        r.triangles,
        r.deforming_meshes,
        r.frames,
        r.rays_per_frame,
        if r.packets { " (as packets)" } else { "" },
        r.threads
    );
    s.push_str(&modelled_table(r));
    s.push_str(&format!(
        "wall clock{}:\n{:<14} {:>10} {:>10} {:>10} {:>9} {:>9} {:>8} {:>8} {:>8} {:>9} {:>8}\n",
        if r.busy {
            " (BUSY: some run waited for a core over 10% of its CPU time; these figures are \
             disturbed)"
        } else {
            ""
        },
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
            "{:<14} {:>10.2} {:>10.2} {:>10.2} {:>9.3} {:>9.3} {:>8} {:>8.3} {:>8.3} {:>9} {:>8}\n",
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
            super::nonzero_or_dash(f64::from(p.max_fresh_ratio), 3),
            super::nonzero_or_dash(p.oracle_ratio, 3)
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
    let with_async = r.policies.iter().any(|p| p.policy == "async");
    if r.lockstep > 1 && with_async {
        s.push_str(
            "async: the engines run in lockstep, so its background builds also run during the \
             other engines' frames; its frame times as an application sees them come from a \
             run of `-p async --no-oracle --no-tlas-compare` alone\n",
        );
    }
    if with_async {
        s.push_str(&format!(
            "async: the background worker ran at {} priority{}\n",
            r.worker_priority,
            if r.worker_priority == WorkerPriority::Normal {
                " (`--worker-priority idle` keeps it off the frames' cores)"
            } else {
                ""
            }
        ));
    }
    s.push_str(&format!(
        "update against trace per frame (medians over {} frames; update = pose + mesh trees + \
         top-level tree; mean update includes rebuilds spread over the frames):\n\
         {:<14} {:>9} {:>9} {:>9} {:>10} {:>10} {:>10} {:>10}  update < trace\n",
        r.frames, "policy", "pose", "meshes", "tlas", "update", "trace", "upd/trace", "mean upd"
    ));
    for p in &r.policies {
        let ratio = (p.median_trace_ms > 0.0).then(|| p.median_update_ms / p.median_trace_ms);
        s.push_str(&format!(
            "{:<14} {:>9.3} {:>9.3} {:>9.4} {:>10.3} {:>10.3} {:>10} {:>10.3}  {}\n",
            format!("{}{}", p.policy, if p.default { "*" } else { "" }),
            p.median_pose_ms,
            p.median_blas_ms,
            p.median_tlas_ms,
            p.median_update_ms,
            p.median_trace_ms,
            super::or_dash(ratio, 3),
            p.update_ms_per_frame,
            match (
                ratio.is_some_and(|r| r < 1.0),
                p.update_ms_per_frame < p.trace_ms_per_frame
            ) {
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
        title: format!("SAH cost against the last build: {}", short(&r.source)),
        x_label: "frame (1 = first)".into(),
        y_label: "largest SAH ratio over meshes (1 = as built)".into(),
        series: by_policy(&|x| f64::from(x.max_sah_ratio), true),
        note: "filled marker: a mesh was rebuilt in that frame;  * the default policy".into(),
        ..Chart::default()
    };
    let time = Chart {
        title: format!("time per frame: {}", short(&r.source)),
        x_label: "frame (1 = first)".into(),
        y_label: "update + trace time per frame (ms, wall clock)".into(),
        series: by_policy(&|x| x.update_ms + x.trace_ms, true),
        log_y: true,
        note: "filled marker: a mesh was rebuilt in that frame;  * the default policy".into(),
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
        title: format!("update cost against trace cost: {}", short(&r.source)),
        x_label: "update time per frame (ms)".into(),
        y_label: "trace time per ray (µs)".into(),
        note: "builder: rebuilt every frame;  policy: refit or rebuild as it decides;  lower left is better"
            .into(),
        series: speed_series,
        log_x: true,
        ..Chart::default()
    };
    let predicted = Chart {
        title: format!(
            "SAH-predicted against counted traversal work: {}",
            short(&r.source)
        ),
        x_label: "predicted nodes + triangles visited per ray (SAH)".into(),
        y_label: "counted nodes + triangles visited per ray".into(),
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
        note: "one marker per frame;  dashed grey: predicted = counted".into(),
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

/// A policy's total over the oracle's on one row, as the sweep judges it: the modelled totals
/// (deterministic) where the row has the modelled oracle, else the wall-clock ones.
#[must_use]
pub fn verdict_ratio(p: &PolicySummary) -> f64 {
    if p.oracle_ratio_modelled > 0.0 {
        p.oracle_ratio_modelled
    } else {
        p.oracle_ratio
    }
}

/// How far above the oracle a row may be for the default's verdict.
pub const VERDICT_MARGIN: f64 = 0.05;

/// The share of the trace passes it is taken in that the default's ray sample may cost on a
/// row (the ray-work measure's budget).
pub const SAMPLE_BUDGET: f64 = 0.02;

/// One policy over the sweep's rows (only rows with an oracle count).
#[derive(Clone, Debug, Serialize)]
pub struct PolicyVerdict {
    /// Policy name.
    pub policy: String,
    /// True for the default policy.
    pub default: bool,
    /// Rows (file and animation) counted.
    pub rows: usize,
    /// Mean total over the oracle's ([`verdict_ratio`]).
    pub mean_ratio: f64,
    /// Largest total over the oracle's.
    pub worst_ratio: f64,
    /// The row of the largest ratio.
    pub worst_source: String,
    /// Rows more than [`VERDICT_MARGIN`] above the oracle.
    pub over_margin: Vec<String>,
    /// Largest ratio over the rows with a deforming mesh (the others run the same trees under
    /// every policy: their ratios are timing noise); 0 without such rows.
    pub worst_deforming_ratio: f64,
    /// The row of `worst_deforming_ratio`.
    pub worst_deforming_source: String,
}

/// What a sweep's table says, computed from it.
#[derive(Clone, Debug, Serialize)]
pub struct SweepConclusion {
    /// True when every row was judged by its modelled totals (deterministic), false when some
    /// had only wall-clock ones (run without the oracle's modelled measure).
    pub modelled: bool,
    /// Per policy, in the table's order.
    pub policies: Vec<PolicyVerdict>,
    /// The policy with the lowest worst ratio (none without rows).
    pub lowest_worst: Option<String>,
    /// The default policy's verdict: within [`VERDICT_MARGIN`] of the oracle on every row
    /// (false without rows).
    pub default_within_margin: bool,
    /// The default policy's sample: its measured share of the trace passes it was taken in
    /// ([`PolicySummary::sample_share`]), mean over the rows that sampled and the largest,
    /// with its row, and the largest modelled share; `None` when no row sampled.
    pub default_sample: Option<SampleVerdict>,
    /// Rows that gave no report (load or run failures).
    pub failures: usize,
}

/// The default policy's sample over a sweep's rows.
#[derive(Clone, Debug, Serialize)]
pub struct SampleVerdict {
    /// Rows on which it sampled.
    pub rows: usize,
    /// Mean measured share.
    pub mean_share: f64,
    /// Largest measured share.
    pub worst_share: f64,
    /// The row of `worst_share`.
    pub worst_source: String,
    /// Rows whose measured share is above [`SAMPLE_BUDGET`].
    pub over_budget: usize,
    /// Largest modelled share.
    pub worst_modelled_share: f64,
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

/// Per policy, the mean and worst ratio to the oracle over the reports that have one
/// ([`verdict_ratio`]); which policy's worst is lowest; whether the default stays within
/// [`VERDICT_MARGIN`] everywhere; what its sample cost.
#[must_use]
pub fn sweep_conclusion(reports: &[Report], failures: usize) -> SweepConclusion {
    let mut policies: Vec<PolicyVerdict> = Vec::new();
    let mut modelled = true;
    let mut sample: Option<SampleVerdict> = None;
    for r in reports.iter().filter(|r| r.oracle.total_ms > 0.0) {
        for p in &r.policies {
            modelled &= p.oracle_ratio_modelled > 0.0;
            let ratio = verdict_ratio(p);
            if p.default && p.sample_share > 0.0 {
                let v = sample.get_or_insert(SampleVerdict {
                    rows: 0,
                    mean_share: 0.0,
                    worst_share: 0.0,
                    worst_source: String::new(),
                    over_budget: 0,
                    worst_modelled_share: 0.0,
                });
                v.rows += 1;
                v.mean_share += p.sample_share;
                if p.sample_share > v.worst_share {
                    v.worst_share = p.sample_share;
                    v.worst_source.clone_from(&r.source);
                }
                v.over_budget += usize::from(p.sample_share > SAMPLE_BUDGET);
                v.worst_modelled_share = v.worst_modelled_share.max(p.sample_share_modelled);
            }
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
                        over_margin: Vec::new(),
                        worst_deforming_ratio: 0.0,
                        worst_deforming_source: String::new(),
                    });
                    policies.len() - 1
                }
            };
            let v = &mut policies[k];
            v.rows += 1;
            v.mean_ratio += ratio;
            if ratio > v.worst_ratio {
                v.worst_ratio = ratio;
                v.worst_source.clone_from(&r.source);
            }
            if ratio > 1.0 + VERDICT_MARGIN {
                v.over_margin.push(r.source.clone());
            }
            if r.deforming_meshes > 0 && ratio > v.worst_deforming_ratio {
                v.worst_deforming_ratio = ratio;
                v.worst_deforming_source.clone_from(&r.source);
            }
        }
    }
    for v in &mut policies {
        v.mean_ratio /= v.rows.max(1) as f64;
    }
    if let Some(v) = &mut sample {
        v.mean_share /= v.rows.max(1) as f64;
    }
    let lowest_worst = policies
        .iter()
        .min_by(|a, b| a.worst_ratio.total_cmp(&b.worst_ratio))
        .map(|v| v.policy.clone());
    let default_within_margin = policies
        .iter()
        .find(|v| v.default)
        .is_some_and(|v| v.rows > 0 && v.over_margin.is_empty());
    SweepConclusion {
        modelled: modelled && !policies.is_empty(),
        policies,
        lowest_worst,
        default_within_margin,
        default_sample: sample,
        failures,
    }
}

/// The conclusion as text.
#[must_use]
pub fn conclusion_text(c: &SweepConclusion) -> String {
    let mut s = format!(
        "Conclusion (computed from the rows above, {}):\n",
        if c.modelled {
            "modelled totals over the oracle's, deterministic"
        } else {
            "wall-clock totals over the oracle's where a row has no modelled measure"
        }
    );
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
    let margin = 100.0 * VERDICT_MARGIN;
    if let Some(d) = c.policies.iter().find(|v| v.default) {
        if c.default_within_margin {
            s.push_str(&format!(
                "  default {}: within {margin:.0}% of the oracle on every row ({} rows; mean {:.4}, \
                 worst {:.4}, {})\n",
                d.policy, d.rows, d.mean_ratio, d.worst_ratio, d.worst_source
            ));
        } else {
            s.push_str(&format!(
                "  default {}: NOT within {margin:.0}% of the oracle on {} of {} rows ({}); mean \
                 {:.4}, worst {:.4}, {}\n",
                d.policy,
                d.over_margin.len(),
                d.rows,
                d.over_margin.join(", "),
                d.mean_ratio,
                d.worst_ratio,
                d.worst_source
            ));
        }
        if let Some(v) = &c.default_sample {
            s.push_str(&format!(
                "  default {}'s ray sample, {} rows: {:.2}% of the trace passes it was taken in \
                 on average, at most {:.2}% ({}); rows above {:.0}%: {}; modelled at most {:.2}%\n",
                d.policy,
                v.rows,
                100.0 * v.mean_share,
                100.0 * v.worst_share,
                v.worst_source,
                100.0 * SAMPLE_BUDGET,
                v.over_budget,
                100.0 * v.worst_modelled_share
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
    s.push_str(if c.modelled {
        "  (modelled totals repeat exactly on every run with the same prices, whatever the \
         machine's load; the sample's share is wall-clock time and moves between runs)\n"
    } else {
        "  (rows without a deforming mesh run the same trees under every policy: their spread \
         around 1 shows the run's timing noise. Ratios within a few percent of 1, either side, \
         are timing noise on a shared machine)\n"
    });
    s
}

/// The sweep table: per file and animation, per policy, total time over the oracle's; then the
/// worst ratio of each policy, the top-level tree comparison (total time over the best
/// top-level policy's on that file), the rows that failed, and the conclusion computed from the
/// rows ([`sweep_conclusion`]).
#[must_use]
pub fn sweep_table(sweep: &Sweep) -> String {
    let mut s = sweep_rows(&sweep.reports, sweep.conclusion.modelled);
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

/// The sweep's table; `modelled` when every row has its modelled ratios
/// ([`SweepConclusion::modelled`]).
fn sweep_rows(reports: &[Report], modelled: bool) -> String {
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
        "{} / oracle ({} frames, {} rays/frame, {} thread(s); * default)\n",
        if modelled {
            "modelled total"
        } else {
            "total time (modelled where the row has it)"
        },
        first.frames,
        first.rays_per_frame,
        first.threads
    );
    // The name column fits the longest name, so that no file name is cut.
    let width = reports
        .iter()
        .map(|r| r.source.chars().count())
        .chain(["file [animation]".len()])
        .max()
        .unwrap_or(0);
    s.push_str(&format!(
        "{:<width$} {:>7} {:>4}",
        "file [animation]", "tris", "dfm"
    ));
    for n in names.iter().chain(&tlas_names) {
        s.push_str(&format!(" {:>w$}", n, w = n.len().max(8)));
    }
    s.push('\n');
    let mut worst = vec![0.0f64; names.len()];
    let mut worst_tlas = vec![0.0f64; tlas_names.len()];
    for r in reports {
        s.push_str(&format!(
            "{:<width$} {:>7} {:>4}",
            r.source, r.triangles, r.deforming_meshes
        ));
        for (k, n) in names.iter().enumerate() {
            let v = r.policies.get(k).map_or(0.0, verdict_ratio);
            worst[k] = worst[k].max(v);
            s.push_str(&format!(
                " {:>w$}",
                super::nonzero_or_dash(v, 3),
                w = n.len().max(8)
            ));
        }
        let best_tlas = r
            .tlas
            .iter()
            .map(|t| t.total_ms)
            .fold(f64::INFINITY, f64::min);
        for (k, n) in tlas_names.iter().enumerate() {
            let v = r.tlas.get(k).map_or(0.0, |t| t.total_ms / best_tlas);
            worst_tlas[k] = worst_tlas[k].max(v);
            s.push_str(&format!(
                " {:>w$}",
                super::nonzero_or_dash(v, 3),
                w = n.len().max(8)
            ));
        }
        s.push('\n');
    }
    s.push_str(&format!("{:<width$} {:>7} {:>4}", "worst", "", ""));
    for (v, n) in worst
        .iter()
        .zip(&names)
        .chain(worst_tlas.iter().zip(&tlas_names))
    {
        s.push_str(&format!(
            " {:>w$}",
            super::nonzero_or_dash(*v, 3),
            w = n.len().max(8)
        ));
    }
    s.push_str("\n(tlas columns: total time over the best top-level policy on that file)\n");
    s
}
