//! The two-level scene: one bottom-level tree (BLAS, a [`MeshBvh`]) per mesh, one top-level
//! tree (TLAS, a [`Bvh`]) over the world boxes of the mesh instances. With
//! [`Traversal::Wide`] (the default) each mesh also keeps an 8-wide tree ([`MeshBvh8`]) that
//! the rays walk, collapsed from the binary one after each (re)build and refitted with it.
//!
//! A mesh whose vertices are written ([`Engine::set_positions`], [`Engine::positions_mut`]) is
//! refitted or rebuilt in the next [`Engine::update`] as the [`Policy`] decides, each mesh on
//! its own; a mesh nobody writes is never touched again. Rays are carried into an instance's
//! space with its inverse transform, the direction not renormalised, so a hit's `t` is the
//! same parameter along the world ray in every instance.
//!
//! After the first frame [`Engine::update`] allocates nothing, rebuilds included: trees are
//! rebuilt into their own storage with one shared [`BuildWorkspace`], and the first
//! [`Engine::add_mesh`] prepares every thread of the current rayon pool, so build the scene and
//! run the frame loop inside that pool's `install` (`docs/internals.md`, "Engine memory").

use super::estimate::FreshSah;
use super::policy::{Action, Decision, Policy, PolicyState};
use super::prices::Prices;
use super::ray_work::{CostMeasure, Degradation, MeshSample, RaySample, SampleEntry};
use super::stats::{FrameStats, MeshStats};
use crate::bvh::ray_order::RayBatch;
use crate::bvh::wide::{Child, NO_PRIM};
use crate::bvh::{
    BuildParams, BuildWorkspace, Bvh, Counters, MeshBvh, MeshBvh8, Node, TraversalStats, WideBvh,
};
use crate::geom::{Aabb, Ray};
use glam::{Affine3A, Vec3};
use rayon::prelude::*;
use std::sync::Mutex;
use std::time::Instant;

mod background;
mod batch;
mod clip;
mod edit;
mod filter;
mod memory;
mod mesh_update;
mod packet;
mod queries;
mod sample;

pub use filter::{HitDetail, QueryFilter};
use mesh_update::{FrameContext, PartialCut, Restructure};
pub use queries::ScenePoint;

/// A mesh of an [`Engine`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MeshId(pub u32);

/// An instance (a placed mesh) of an [`Engine`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct InstanceId(pub u32);

/// How the top-level tree follows moving instances.
///
/// The default is [`TlasPolicy::Rebuild`]: the top-level tree holds one box per instance, so
/// a rebuild is cheap next to the frame and every frame traces through a fresh tree, while a
/// refitted top-level tree over many moving instances degrades and traces slower (the runs
/// behind this are in `docs/internals.md`, "Constants and the runs behind them"). A rebuild
/// goes into the existing tree with the engine's build workspace and allocates nothing once
/// warm.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub enum TlasPolicy {
    /// Always refit (rebuilt only when instances are added).
    Refit,
    /// Rebuild every frame something moved.
    Rebuild,
    /// Refit, and rebuild when its SAH ratio passes the value.
    Threshold(f32),
}

impl TlasPolicy {
    /// The engine's default (see the type's docs).
    pub const DEFAULT: TlasPolicy = TlasPolicy::Rebuild;
}

/// What an [`Engine`] is built with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EngineConfig {
    /// Builder for every tree.
    pub build: BuildParams,
    /// Refit-or-rebuild policy of the meshes.
    pub policy: Policy,
    /// Policy of the top-level tree.
    pub tlas: TlasPolicy,
    /// Where the policy's costs of refits, rebuilds and estimates come from.
    pub timing: Timing,
    /// Which mesh trees rays walk.
    pub traversal: Traversal,
    /// What the policies measure degradation and trace cost by.
    pub cost: CostMeasure,
    /// Unit prices of the modelled costs: what [`Timing::Priced`] decides with, and what the
    /// statistics' modelled figures are priced at whatever the timing.
    pub prices: Prices,
    /// The scheduling class of the background rebuild's worker ([`Policy::Async`]).
    pub worker: WorkerPriority,
    /// Take the ray-work sample under a policy that does not read it too (`refit`, `rebuild`,
    /// `periodic`: [`PolicyState::reads_sample`]), for the statistics it feeds (the frame's
    /// sampled work, [`Engine::mesh_trace_share`]), as `bench` does to compare its runs. Off by
    /// default: those policies' frames then pay nothing for it.
    pub always_sample: bool,
}

/// The scheduling class of the background rebuild's worker thread.
///
/// [`WorkerPriority::Idle`] (Linux `SCHED_IDLE`) runs the build only on cycles no thread of
/// normal priority wants, so that the frames beside it keep their pace (`docs/ladder.md`);
/// on a machine whose cores other work keeps busy it may get next to none, and the engine then
/// waits for the build at its due frame for as long as it takes, so it is opt-in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum WorkerPriority {
    /// The default: the system shares the cores between the worker and the frame loop.
    #[default]
    Normal,
    /// The scheduler's idle class (Linux; elsewhere the same as `Normal`).
    Idle,
}

impl std::str::FromStr for WorkerPriority {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "normal" => Ok(Self::Normal),
            "idle" => Ok(Self::Idle),
            _ => Err(format!("worker priority {s:?}: expected normal or idle")),
        }
    }
}

impl std::fmt::Display for WorkerPriority {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Normal => "normal",
            Self::Idle => "idle",
        })
    }
}

/// Which tree of each mesh the engine's rays walk (the top-level tree is binary either way).
///
/// With [`Traversal::Wide`] every mesh keeps, beside its binary tree, an 8-wide tree
/// ([`MeshBvh8`]) that all ray queries (single rays and packets) walk: it is collapsed from the
/// binary tree after each build or rebuild (into its own storage, allocating nothing once
/// warm) and refitted after each refit. The binary tree stays: its SAH is what the policy
/// weighs, and rebuilds build it. The wide tree's refit and collapse are part of the update
/// and counted in the refit and rebuild times the policy sees.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Traversal {
    /// Rays walk the binary trees.
    Binary,
    /// Rays walk 8-wide trees kept beside the binary ones.
    Wide,
}

impl Traversal {
    /// The engine's default, [`Traversal::Wide`]: the wide tree traces single rays and packets
    /// faster than the binary one, which outweighs the collapse each rebuild adds (the policy
    /// sees that cost); see `docs/packets.md`, "The engine on the wide trees".
    pub const DEFAULT: Traversal = Traversal::Wide;
}

impl std::str::FromStr for Traversal {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "binary" => Ok(Self::Binary),
            "wide" => Ok(Self::Wide),
            _ => Err(format!("traversal {s:?}: expected binary or wide")),
        }
    }
}

impl std::fmt::Display for Traversal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Binary => "binary",
            Self::Wide => "wide",
        })
    }
}

impl Default for EngineConfig {
    fn default() -> Self {
        Self {
            build: BuildParams::BINNED,
            policy: Policy::DEFAULT,
            tlas: TlasPolicy::DEFAULT,
            timing: Timing::Measured,
            traversal: Traversal::DEFAULT,
            cost: CostMeasure::default(),
            prices: Prices::default(),
            worker: WorkerPriority::Normal,
            always_sample: false,
        }
    }
}

/// Where the costs the amortized policy weighs come from: the time of a rebuild, of a refit
/// (which pays for the fresh-build estimate and for refitting a replaced tree on probation) and
/// of the estimate itself. The trace time always comes from [`Engine::record_trace`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Timing {
    /// Timed with the wall clock as the engine runs, so the decisions follow the machine and
    /// its load: the default.
    Measured,
    /// Every cost from work counts at the configuration's [`Prices`]: refits and rebuilds by
    /// their triangles, estimates by their subsample, and the trace time by the ray-work
    /// sample (when the frame's rays were sampled; else the recorded time). The same frames and
    /// rays give the same decisions on every run, whatever the machine's load.
    Priced,
    /// Costs in proportion to the triangles worked on, so the same frames and recorded trace
    /// times give the same decisions on every run and machine (reproducible simulations,
    /// tests). Frame statistics still report the measured times.
    Modeled {
        /// Cost of refitting one triangle, ns.
        refit_ns_per_tri: f64,
        /// Cost of rebuilding over one triangle, ns.
        rebuild_ns_per_tri: f64,
        /// Cost of the fresh-build estimate per triangle of its subsample, ns.
        estimate_ns_per_tri: f64,
    },
}

impl Timing {
    /// The cost (ms) the policy uses for a refit over `tris` triangles measured at `ms`.
    #[must_use]
    pub fn refit_ms(self, ms: f64, tris: usize, prices: &Prices) -> f64 {
        match self {
            Self::Measured => ms,
            Self::Priced => prices.refit_ms(tris),
            Self::Modeled {
                refit_ns_per_tri, ..
            } => refit_ns_per_tri * tris as f64 * 1e-6,
        }
    }

    /// The cost (ms) the policy uses for a rebuild over `tris` triangles measured at `ms`.
    #[must_use]
    pub fn build_ms(self, ms: f64, tris: usize, prices: &Prices) -> f64 {
        match self {
            Self::Measured => ms,
            Self::Priced => prices.rebuild_ms(tris),
            Self::Modeled {
                rebuild_ns_per_tri, ..
            } => rebuild_ns_per_tri * tris as f64 * 1e-6,
        }
    }

    /// The cost (ms) the policy uses for a clip-aware rebuild over `tris` triangles for
    /// `poses` sampled poses (a plain rebuild with none) measured at `ms`.
    #[must_use]
    pub fn clip_build_ms(self, ms: f64, tris: usize, poses: usize, prices: &Prices) -> f64 {
        match self {
            Self::Measured => ms,
            Self::Priced => prices.clip_rebuild_ms(tris, poses),
            Self::Modeled {
                rebuild_ns_per_tri, ..
            } => rebuild_ns_per_tri * tris as f64 * (1 + poses * poses) as f64 * 1e-6,
        }
    }

    /// The cost (ms) the policy uses for an estimate over a subsample of `tris` triangles
    /// measured at `ms`.
    #[must_use]
    pub fn estimate_ms(self, ms: f64, tris: usize, prices: &Prices) -> f64 {
        match self {
            Self::Measured => ms,
            Self::Priced => prices.estimate_ms(tris),
            Self::Modeled {
                estimate_ns_per_tri,
                ..
            } => estimate_ns_per_tri * tris as f64 * 1e-6,
        }
    }
}

/// A ray's closest hit in the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneHit {
    /// Distance along the world ray, in units of its direction.
    pub t: f32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex.
    pub v: f32,
    /// Triangle index within the instance's mesh.
    pub prim: u32,
    /// The instance hit.
    pub instance: InstanceId,
}

struct MeshEntry {
    positions: Vec<Vec3>,
    indices: Vec<[u32; 3]>,
    bvh: MeshBvh,
    /// With [`Traversal::Wide`], the 8-wide tree rays walk, collapsed from `bvh`.
    wide: Option<MeshBvh8>,
    /// While probing, the tree the last rebuild replaced, refitted alongside; otherwise spare
    /// storage the next probed or trial rebuild goes into.
    prev: MeshBvh,
    /// Spare storage for the wide tree a trial rebuild replaces (see [`Engine::trials`]).
    prev_wide: Option<MeshBvh8>,
    probe: Option<Probe>,
    sah: f32,
    dirty: bool,
    moved: bool,
    state: PolicyState,
    /// Subsample and scratch of the fresh-build estimate.
    fresh: FreshSah,
    /// The latest fresh-build estimate, and what computing it took (ms).
    last_estimate: f32,
    estimate_ms: f64,
    /// Time (ms) the estimate may still spend: it earns [`ESTIMATE_SHARE`] of each frame's
    /// refit and trace time, and is re-estimated only when it has earned the estimate's cost.
    estimate_budget: f64,
    stats: MeshStats,
    /// Sum over its instances of world box area times SAH: its share of the trace cost.
    weight: f64,
    /// Sum over its visible instances of their world box's half area.
    world_area: f64,
    /// Ray-work measure: the sampled work into this mesh since its tree was built, over the
    /// fresh tree's.
    degradation: Degradation,
    /// The subtrees a partial rebuild keeps or rebuilds (taken at each full build when the
    /// policy may rebuild partly).
    cut: PartialCut,
    /// Removed ([`Engine::remove_mesh`]): empty, never placed again.
    removed: bool,
    /// Its tree's node storage (and the spare's) holds any tree over its triangles: set at its
    /// first update as a deforming mesh, so that no rebuild after it grows the storage.
    any_shape: bool,
    /// The sampled poses of its clip still ahead, which its rebuilds are built for
    /// ([`Engine::set_clip_ahead`]).
    clip: clip::ClipAhead,
    /// Poses its last (re)build was made for (0: a plain build of one pose).
    build_poses: usize,
    /// Added as never deforming ([`Engine::add_static_mesh`]): built once, no spare trees,
    /// estimate, cut or ray sample, and with the wide traversal no binary tree (`bvh` is
    /// empty).
    fixed: bool,
}

impl MeshEntry {
    /// The box of its triangles, from whichever tree it keeps.
    fn bounds(&self) -> Aabb {
        match &self.wide {
            Some(w) if self.fixed => w.bounds(),
            _ => self.bvh.bvh().bounds(),
        }
    }
}

/// A rebuild on probation: the tree it replaced is refitted alongside until the new tree has
/// saved what the rebuild cost (it paid), the old one is better again (back to it: it did not
/// pay), or refitting the old one has cost [`PROBE_SHARE`] of the rebuild (undecided). Under
/// the SAH measure every probed rebuild, compared by the SAH each frame; under the ray-work
/// measure a kept trial, compared on the sampled rays at some frames ([`ray_probe_step`]).
#[derive(Clone, Copy)]
struct Probe {
    /// Policy state of the replaced tree, restored if it wins.
    state: PolicyState,
    /// Trace time the new tree has saved so far (the last recorded trace time times the old
    /// tree's SAH over the new one's, minus one), ms.
    saved_ms: f64,
    /// Time spent refitting the old tree alongside, ms.
    cost_ms: f64,
    /// What the rebuild cost, ms.
    rebuild_ms: f64,
    /// Frames since the rebuild.
    frames: u32,
    /// Frames since the rebuild at which the next comparison is due (ray-work measure).
    next: u32,
    /// Frames since the rebuild at the last comparison.
    last: u32,
    /// The replaced tree's ray-work degradation, restored with it (ray-work measure).
    degradation: Degradation,
}

#[derive(Clone, Copy)]
struct InstanceEntry {
    mesh: u32,
    transform: Affine3A,
    inverse: Affine3A,
    identity: bool,
    visible: bool,
    dirty: bool,
    /// Index among the top-level tree's primitives, if its mesh has triangles.
    tlas_prim: Option<u32>,
    /// Visibility mask, ANDed with a query's ([`QueryFilter::mask`]).
    mask: u32,
    /// Removed ([`Engine::remove_instance`]): never seen by queries again.
    removed: bool,
}

/// The dynamic scene: add meshes and instances, write vertex positions or transforms, call
/// [`Engine::update`], cast rays.
///
/// ```
/// use dynbvh::engine::{Engine, EngineConfig};
/// use dynbvh::geom::Ray;
/// use glam::{Affine3A, Vec3};
///
/// let mut e = Engine::new(EngineConfig::default());
/// let quad = e.add_mesh(
///     vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
///     vec![[0, 1, 2], [0, 2, 3]],
/// );
/// let a = e.add_instance(quad, Affine3A::IDENTITY);
/// let b = e.add_instance(quad, Affine3A::from_translation(Vec3::new(0.0, 0.0, -2.0)));
/// e.update();
/// let ray = Ray::new(Vec3::new(0.25, 0.75, 1.0), -Vec3::Z);
/// assert_eq!(e.closest_hit(&ray).unwrap().instance, a);
/// // Lift the second quad above the first, and move one vertex of the mesh.
/// e.set_transform(b, Affine3A::from_translation(Vec3::new(0.0, 0.0, 0.5)));
/// e.positions_mut(quad)[3] = Vec3::new(0.0, 1.0, 0.1);
/// e.update();
/// let hit = e.closest_hit(&ray).unwrap();
/// assert_eq!(hit.instance, b);
/// assert!(e.any_hit(&ray));
/// ```
pub struct Engine {
    config: EngineConfig,
    meshes: Vec<MeshEntry>,
    instances: Vec<InstanceEntry>,
    /// Instance of each top-level primitive.
    tlas_instances: Vec<u32>,
    /// World box of each top-level primitive.
    tlas_boxes: Vec<Aabb>,
    tlas: Bvh,
    tlas_build_sah: f32,
    tlas_stale: bool,
    /// Scratch of every build (meshes and top-level tree), kept so that a rebuild into an
    /// existing tree allocates nothing once it has grown to the largest mesh.
    workspace: BuildWorkspace,
    /// Pose time recorded since the last update, reported by the next.
    pending_pose_ms: f64,
    /// Set once the rayon pool's threads have their build scratch
    /// ([`crate::bvh::build::prepare_threads`]).
    threads_ready: bool,
    frame: u64,
    stats: FrameStats,
    /// The ray-work sample of the frame traced last ([`Engine::sample_rays`]).
    sample: RaySample,
    /// Its sampled rays' entries into instances.
    entries: Vec<SampleEntry>,
    /// Its entries and work per mesh.
    mesh_samples: Vec<MeshSample>,
    /// Scratch of optimisations and partial rebuilds.
    restructure: Restructure,
    /// The background rebuild's worker ([`Policy::Async`]).
    background: background::Background,
    /// The last sampled frame's trace cost (ms, modelled under [`Timing::Priced`]): how many
    /// frames a background rebuild is given.
    frame_trace_ms: f64,
    /// The frame count at which the run ends, when it is known ([`Engine::plan_frames`]).
    horizon: Option<u64>,
    /// A mesh was added since the last sampled trace.
    unsampled_meshes: bool,
    /// The next update's action for every mesh that moved, in place of the policy's
    /// ([`Engine::force_next`]).
    forced: Option<Decision>,
    /// Scratch of the batch queries that reorder large incoherent batches
    /// ([`crate::bvh::ray_order`]); a batch that finds it in use goes as it comes.
    order: Mutex<RayBatch>,
}

impl Engine {
    /// An empty scene.
    #[must_use]
    pub fn new(config: EngineConfig) -> Self {
        Self {
            config,
            meshes: Vec::new(),
            instances: Vec::new(),
            tlas_instances: Vec::new(),
            tlas_boxes: Vec::new(),
            tlas: Bvh::empty(config.build.max_leaf_size),
            tlas_build_sah: 0.0,
            tlas_stale: true,
            workspace: BuildWorkspace::default(),
            pending_pose_ms: 0.0,
            threads_ready: false,
            frame: 0,
            stats: FrameStats::default(),
            sample: RaySample::new(u64::MAX),
            entries: Vec::new(),
            mesh_samples: Vec::new(),
            restructure: Restructure::default(),
            background: background::Background::new(config.worker),
            frame_trace_ms: 0.0,
            horizon: None,
            unsampled_meshes: false,
            forced: None,
            order: Mutex::default(),
        }
    }

    /// Tells the policy that the run makes `updates` more updates (and traces after each), so
    /// that it acts only where the action pays for itself before the end: a rebuild that
    /// cannot is left out. `None` (the default): open-ended. Past the planned frames the run
    /// is open-ended again.
    pub fn plan_frames(&mut self, updates: Option<u64>) {
        self.horizon = updates.map(|n| self.frame + n);
    }

    /// True when rebuilds are probed (the replaced tree kept and refitted alongside): the
    /// amortized policy under the SAH measure. Under the ray-work measure rebuilds are trials
    /// instead, and a kept trial is on probation only where its estimate is in doubt
    /// ([`ray_probe_step`]).
    fn probes(&self) -> bool {
        PolicyState::probes_rebuilds(self.config.policy) && self.config.cost == CostMeasure::Sah
    }

    /// True when the policy's rebuilds go into a spare tree, kept reserved for them.
    fn keeps_spare(&self) -> bool {
        self.probes() || self.trials()
    }

    /// True when the policy's rebuilds (`amortized`'s and the ladder's) are trials: under the
    /// ray-work measure, the refitted tree is kept until the previous frame's sampled rays,
    /// replayed on both, have judged the new one, and stays if the new one does worse (a
    /// binned SAH build is a heuristic: on the rays actually cast it is not always the better
    /// tree).
    fn trials(&self) -> bool {
        matches!(self.config.policy, Policy::Amortized | Policy::Ladder)
            && self.config.cost == CostMeasure::Rays
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &EngineConfig {
        &self.config
    }

    /// Makes the next update take `decision` for every mesh whose vertices moved, in place of
    /// what the policy would decide (the policy's state is not told): a schedule scripted frame
    /// by frame, as the oracle's pass and its tests play them.
    pub fn force_next(&mut self, decision: Decision) {
        self.forced = Some(decision);
    }

    /// Changes the mesh policy from the next update on. Switching to a policy that keeps the
    /// trees rebuilds replace ([`Policy::Amortized`]) reserves every mesh's spare tree now, so
    /// that the frame loop still allocates nothing.
    pub fn set_policy(&mut self, policy: Policy) {
        self.config.policy = policy;
        // Static meshes never update: they need none of what the policy keeps.
        if MeshEntry::wants_cut(policy) {
            for m in self.meshes.iter_mut().filter(|m| !m.fixed) {
                m.cut.reset(&m.bvh, &mut self.restructure.partial);
                m.bvh.reserve_any_shape();
            }
        }
        if policy.uses_rungs() {
            for m in self.meshes.iter().filter(|m| !m.fixed) {
                self.restructure.warm_up(&m.bvh, &self.config.build);
            }
        }
        if self.keeps_spare() {
            for m in self.meshes.iter_mut().filter(|m| !m.fixed) {
                m.prev.reserve_like(&m.bvh);
            }
        }
        if self.trials() {
            for m in self.meshes.iter_mut().filter(|m| !m.fixed) {
                if m.prev_wide.is_none() && !m.removed {
                    m.prev_wide = m.wide.as_ref().map(spare_wide);
                }
            }
        }
        if policy == Policy::Async {
            for m in self.meshes.iter().filter(|m| !m.fixed) {
                self.background.reserve(
                    m.positions.len(),
                    m.indices.len(),
                    &m.bvh,
                    m.wide.as_ref(),
                );
            }
        }
    }

    /// Adds a mesh and builds its tree now (the build time seeds the amortized policy's cost of
    /// a rebuild).
    ///
    /// # Panics
    /// When a vertex index is out of range.
    pub fn add_mesh(&mut self, positions: Vec<Vec3>, indices: Vec<[u32; 3]>) -> MeshId {
        let entry = self.new_mesh_entry(positions, indices, false);
        self.meshes.push(entry);
        self.mesh_samples.push(MeshSample::default());
        self.unsampled_meshes = true;
        MeshId(self.meshes.len() as u32 - 1)
    }

    /// Adds a mesh whose vertices never move (its instances may: a static or rigid object)
    /// and builds its tree now, keeping no more than its queries need: no spare trees,
    /// degradation estimate, partial-rebuild cut or ray sample, and with [`Traversal::Wide`]
    /// only the 8-wide tree, built straight from the mesh ([`MeshBvh8::build_indexed`]: no
    /// copy of the triangles beside the binary tree it is collapsed from, which is dropped,
    /// and no growth of the workspace the engine keeps for rebuilds; [`Engine::mesh_bvh`] is
    /// then empty).
    /// The same tree as [`Engine::add_mesh`]'s, so every query answers alike.
    /// Writing its positions later ([`Engine::positions_mut`]) makes it an ordinary mesh,
    /// its trees built again from its current positions then (allocating).
    ///
    /// # Panics
    /// When a vertex index is out of range.
    pub fn add_static_mesh(&mut self, positions: Vec<Vec3>, indices: Vec<[u32; 3]>) -> MeshId {
        let entry = self.new_mesh_entry(positions, indices, true);
        self.meshes.push(entry);
        self.mesh_samples.push(MeshSample::default());
        // No ray sample is owed to it: nothing measures its degradation.
        MeshId(self.meshes.len() as u32 - 1)
    }

    /// A mesh's entry with its trees built and its policy state seeded (`fixed`: a static
    /// mesh's, see [`Engine::add_static_mesh`]).
    ///
    /// # Panics
    /// When a vertex index is out of range.
    fn new_mesh_entry(
        &mut self,
        positions: Vec<Vec3>,
        indices: Vec<[u32; 3]>,
        fixed: bool,
    ) -> MeshEntry {
        let n = positions.len();
        assert!(
            indices.iter().flatten().all(|&i| (i as usize) < n),
            "vertex index out of range"
        );
        if !self.threads_ready {
            crate::bvh::build::prepare_threads();
            self.threads_ready = true;
        }
        let t = Instant::now();
        let wide_walk = self.config.traversal == Traversal::Wide;
        let mut bvh = MeshBvh::default();
        let (sah, wide) = if fixed && wide_walk {
            // Only the wide tree is kept: built straight from the mesh, without the binary
            // tree's copy of the triangles, and in the engine's workspace only where that
            // holds it already (it is sized for the meshes the engine rebuilds, and kept).
            let build = &self.config.build;
            let tree = if self.workspace.holds(indices.len(), build) {
                MeshBvh::tree_only(&positions, &indices, build, &mut self.workspace)
            } else {
                MeshBvh::tree_only(&positions, &indices, build, &mut BuildWorkspace::one_shot())
            };
            let wide = MeshBvh8::from_tree_indexed(&tree, &positions, &indices);
            (tree_sah(&tree), Some(wide))
        } else {
            bvh.rebuild_indexed(
                &positions,
                &indices,
                &self.config.build,
                &mut self.workspace,
            );
            let sah = tree_sah(bvh.bvh());
            (sah, wide_walk.then(|| MeshBvh8::from_mesh_bvh(&bvh)))
        };
        let ms = ms_since(t);
        let timing = self.config.timing;
        let prices = self.config.prices;
        let mut state = PolicyState::default();
        let mut prev = MeshBvh::default();
        let mut cut = PartialCut::default();
        let mut prev_wide = None;
        let (mut fresh, mut estimate, mut estimate_ms) = (FreshSah::default(), sah, 0.0);
        if !fixed {
            fresh = FreshSah::new(indices.len(), self.config.build.max_leaf_size);
            let t = Instant::now();
            estimate = fresh.estimate(&positions, &indices);
            estimate_ms = timing.estimate_ms(ms_since(t), fresh.sample_len(), &prices);
            // The spare a probed rebuild goes into, reserved now so that the frame loop never
            // allocates it (address space only until the first probed rebuild writes it).
            if self.keeps_spare() {
                prev.reserve_like(&bvh);
            }
            prev_wide = wide.as_ref().filter(|_| self.trials()).map(spare_wide);
            if MeshEntry::wants_cut(self.config.policy) {
                cut.reset(&bvh, &mut self.restructure.partial);
                bvh.reserve_any_shape();
            }
            if self.config.policy.uses_rungs() {
                self.restructure.warm_up(&bvh, &self.config.build);
            }
            if self.config.policy == Policy::Async {
                self.background
                    .reserve(positions.len(), indices.len(), &bvh, wide.as_ref());
            }
        }
        state.rebuilt(sah, estimate, timing.build_ms(ms, indices.len(), &prices));
        MeshEntry {
            positions,
            indices,
            bvh,
            wide,
            prev,
            prev_wide,
            probe: None,
            sah,
            dirty: false,
            moved: true,
            state,
            fresh,
            last_estimate: estimate,
            estimate_ms,
            estimate_budget: 0.0,
            stats: MeshStats {
                action: Action::Rebuild,
                rebuild_ms: ms,
                sah,
                sah_ratio: 1.0,
                fresh_ratio: 1.0,
                ..MeshStats::default()
            },
            weight: 0.0,
            world_area: 0.0,
            degradation: Degradation::default(),
            cut,
            removed: false,
            any_shape: false,
            clip: clip::ClipAhead::default(),
            build_poses: 0,
            fixed,
        }
    }

    /// Places `mesh` with `transform` (mesh space to world space).
    ///
    /// # Panics
    /// When `mesh` is not a live mesh of this engine.
    pub fn add_instance(&mut self, mesh: MeshId, transform: Affine3A) -> InstanceId {
        assert!(self.is_live_mesh(mesh), "no live mesh {mesh:?}");
        let mut inst = InstanceEntry {
            mesh: mesh.0,
            transform: Affine3A::IDENTITY,
            inverse: Affine3A::IDENTITY,
            identity: true,
            visible: true,
            dirty: true,
            tlas_prim: None,
            mask: u32::MAX,
            removed: false,
        };
        set_transform(&mut inst, transform);
        if !self.meshes[mesh.0 as usize].indices.is_empty() {
            inst.tlas_prim = Some(self.tlas_boxes.len() as u32);
            self.tlas_instances.push(self.instances.len() as u32);
            self.tlas_boxes.push(Aabb::EMPTY);
        }
        self.instances.push(inst);
        self.tlas_stale = true;
        InstanceId(self.instances.len() as u32 - 1)
    }

    /// Number of meshes.
    #[must_use]
    pub fn mesh_count(&self) -> usize {
        self.meshes.len()
    }

    /// Number of instances.
    #[must_use]
    pub fn instance_count(&self) -> usize {
        self.instances.len()
    }

    /// The mesh an instance places.
    #[must_use]
    pub fn instance_mesh(&self, i: InstanceId) -> MeshId {
        MeshId(self.instances[i.0 as usize].mesh)
    }

    /// Replaces the vertex positions of `mesh` (same count); its tree follows at the next
    /// update.
    ///
    /// # Panics
    /// When the vertex count differs.
    pub fn set_positions(&mut self, mesh: MeshId, positions: &[Vec3]) {
        self.positions_mut(mesh).copy_from_slice(positions);
    }

    /// The vertex positions of `mesh`, to write in place; its tree follows at the next update.
    /// A static mesh ([`Engine::add_static_mesh`]) becomes an ordinary one here, its trees
    /// built again from its current positions (allocating).
    pub fn positions_mut(&mut self, mesh: MeshId) -> &mut [Vec3] {
        let i = mesh.0 as usize;
        if self.meshes[i].fixed && !self.meshes[i].removed {
            let positions = std::mem::take(&mut self.meshes[i].positions);
            let indices = std::mem::take(&mut self.meshes[i].indices);
            self.meshes[i] = self.new_mesh_entry(positions, indices, false);
            // Its fresh tree's work on the next sample is its reference, as a new mesh's.
            self.unsampled_meshes = true;
            for inst in self.instances.iter_mut().filter(|inst| inst.mesh == mesh.0) {
                inst.dirty = true;
            }
        }
        let m = &mut self.meshes[i];
        m.dirty = !m.removed;
        &mut m.positions
    }

    /// The vertex positions of `mesh`.
    #[must_use]
    pub fn positions(&self, mesh: MeshId) -> &[Vec3] {
        &self.meshes[mesh.0 as usize].positions
    }

    /// The triangles of `mesh`.
    #[must_use]
    pub fn indices(&self, mesh: MeshId) -> &[[u32; 3]] {
        &self.meshes[mesh.0 as usize].indices
    }

    /// Moves an instance. A transform that cannot be inverted (a zero scale) hides it.
    ///
    /// # Panics
    /// When the instance was removed ([`Engine::remove_instance`]).
    pub fn set_transform(&mut self, i: InstanceId, transform: Affine3A) {
        let inst = &mut self.instances[i.0 as usize];
        assert!(!inst.removed, "instance {i:?} was removed");
        if inst.transform != transform {
            set_transform(inst, transform);
        }
    }

    /// Transform of an instance.
    #[must_use]
    pub fn transform(&self, i: InstanceId) -> Affine3A {
        self.instances[i.0 as usize].transform
    }

    /// Tells the engine how long posing the next frame took: the time is reported in the
    /// statistics of the next [`Engine::update`] (as `pose_ms`, and counted in `update_ms`).
    /// Calls before one update add up.
    pub fn record_pose(&mut self, ms: f64) {
        self.pending_pose_ms += ms;
    }

    /// Tells the engine how long this frame's rays took: the amortized policy predicts each
    /// mesh's share of it from the SAH. The batch queries ([`Engine::trace_closest`],
    /// [`Engine::trace_any`], [`Engine::trace_closest_packets`], [`Engine::trace_any_packets`])
    /// and [`Engine::trace_scope`] call it; call it yourself only for rays cast through the
    /// `&self` queries outside a scope.
    pub fn record_trace(&mut self, ms: f64, rays: u64) {
        let s = &mut self.stats;
        s.trace_ms += ms;
        s.rays += rays;
        s.mrays = if s.trace_ms > 0.0 {
            s.rays as f64 / (s.trace_ms * 1e3)
        } else {
            0.0
        };
        let total: f64 = self.meshes.iter().map(|m| m.weight).sum();
        if total > 0.0 {
            for m in &mut self.meshes {
                m.state.trace_share_ms = s.trace_ms * m.weight / total;
                m.state.traced_ratio = if m.stats.fresh_ratio > 0.0 {
                    m.stats.fresh_ratio
                } else {
                    m.stats.sah_ratio
                };
            }
        }
    }

    /// Brings every tree up to date with the positions and transforms written since the last
    /// update, and returns the frame's statistics so far (trace figures come with
    /// [`Engine::record_trace`]).
    pub fn update(&mut self) -> &FrameStats {
        self.apply_sample();
        let mut stats = self.begin_frame();
        self.update_meshes(&mut stats);
        self.update_tlas(&mut stats);
        self.scene_cost(&mut stats);
        stats.update_ms = stats.pose_ms + stats.refit_ms + stats.rebuild_ms + stats.tlas_ms;
        self.stats = stats;
        self.frame += 1;
        &self.stats
    }

    /// The frame's statistics before any work.
    fn begin_frame(&mut self) -> FrameStats {
        let estimate = PolicyState::needs_fresh_ratio(self.config.policy)
            && self.config.cost == CostMeasure::Sah;
        FrameStats {
            frame: self.frame,
            pose_ms: std::mem::take(&mut self.pending_pose_ms),
            sah_ratio: 1.0,
            max_sah_ratio: 1.0,
            max_fresh_ratio: if estimate { 1.0 } else { 0.0 },
            tlas_sah_ratio: 1.0,
            ..FrameStats::default()
        }
    }

    /// Every mesh whose vertices moved goes through its pipeline ([`MeshEntry::update`]).
    fn update_meshes(&mut self, stats: &mut FrameStats) {
        let policy = self.config.policy;
        let rays_cost = self.config.cost == CostMeasure::Rays;
        // The SAH measure estimates a fresh build's cost by a quick build; the ray-work measure
        // compares the sampled work with the fresh tree's instead (for the threshold policy
        // too: both against a fresh tree).
        let estimate = PolicyState::needs_fresh_ratio(policy) && !rays_cost;
        let ray_judged = rays_cost
            && (PolicyState::needs_fresh_ratio(policy) || matches!(policy, Policy::Threshold(_)));
        // The previous frame's sampled rays, replayed on both trees at a rebuild.
        let replay = rays_cost && self.sample.frame == self.frame && self.sample.sampled > 0;
        // A scripted schedule's rebuilds stand, whatever the replay says.
        let trials = self.trials() && self.forced.is_none();
        let mut cx = FrameContext {
            policy,
            build: self.config.build,
            timing: self.config.timing,
            prices: self.config.prices,
            estimate,
            ray_judged,
            probes: self.probes(),
            trials,
            spare: self.keeps_spare(),
            entries: if replay { &self.entries } else { &[] },
            sampled: replay,
            watched: rays_cost && PolicyState::needs_fresh_ratio(policy),
            workspace: &mut self.workspace,
            restructure: &mut self.restructure,
            background: &mut self.background,
            frame: self.frame,
            frame_trace_ms: self.frame_trace_ms,
            forced: self.forced.take(),
            frames_left: self
                .horizon
                .and_then(|h| h.checked_sub(self.frame))
                .filter(|&n| n > 0),
        };
        let mut restructured = Action::None;
        let mut background = Action::None;
        for (id, m) in self.meshes.iter_mut().enumerate() {
            m.moved = std::mem::take(&mut m.dirty);
            if !m.moved {
                m.stats.model_ms = 0.0;
                m.stats.measured_work_ratio = 0.0;
                m.stats.action = Action::None;
                m.stats.refit_ms = 0.0;
                m.stats.rebuild_ms = 0.0;
                continue;
            }
            let out = m.update(MeshId(id as u32), &mut cx);
            stats.reverts += u32::from(out.reverted);
            if out.swapped {
                stats.rebuilds += 1;
                background = Action::AsyncSwap;
            }
            match m.stats.action {
                Action::Rebuild => stats.rebuilds += 1,
                Action::AsyncSwap => stats.refits += 1,
                Action::AsyncStart => {
                    stats.refits += 1;
                    if background == Action::None {
                        background = Action::AsyncStart;
                    }
                }
                a @ (Action::Optimize | Action::Partial) => {
                    stats.restructures += 1;
                    restructured = a;
                }
                _ => stats.refits += 1,
            }
            stats.refit_ms += m.stats.refit_ms;
            stats.rebuild_ms += m.stats.rebuild_ms;
            stats.model_update_ms += m.stats.model_ms;
            stats.max_sah_ratio = stats.max_sah_ratio.max(m.stats.sah_ratio);
            stats.max_fresh_ratio = stats.max_fresh_ratio.max(m.stats.fresh_ratio);
        }
        stats.action = if background != Action::None {
            background
        } else if stats.rebuilds > 0 {
            Action::Rebuild
        } else if stats.restructures > 0 {
            restructured
        } else if stats.refits > 0 {
            Action::Refit
        } else {
            Action::None
        };
    }

    /// Instance boxes and the top-level tree.
    fn update_tlas(&mut self, stats: &mut FrameStats) {
        let t = Instant::now();
        let mut moved = false;
        for inst in &mut self.instances {
            let m = &self.meshes[inst.mesh as usize];
            if !(inst.dirty || m.moved) {
                continue;
            }
            inst.dirty = false;
            if let Some(p) = inst.tlas_prim {
                self.tlas_boxes[p as usize] = if inst.visible {
                    transform_box(&inst.transform, m.bounds())
                } else {
                    let o = inst.transform.translation.into();
                    Aabb::new(o, o)
                };
                moved = true;
            }
        }
        if self.tlas_stale || (moved && self.config.tlas == TlasPolicy::Rebuild) {
            self.rebuild_tlas();
            stats.tlas_rebuilt = true;
        } else if moved {
            let boxes = &self.tlas_boxes;
            self.tlas.refit(|p| boxes[p as usize]);
            let r = ratio(tree_sah(&self.tlas), self.tlas_build_sah);
            stats.tlas_sah_ratio = r;
            if matches!(self.config.tlas, TlasPolicy::Threshold(max) if r > max) {
                self.rebuild_tlas();
                stats.tlas_rebuilt = true;
                stats.tlas_sah_ratio = 1.0;
            }
        }
        stats.tlas_ms = ms_since(t);
    }

    /// Scene cost: top-level nodes, plus each instance's tree weighted by its box's area.
    fn scene_cost(&mut self, stats: &mut FrameStats) {
        for m in &mut self.meshes {
            m.weight = 0.0;
            m.world_area = 0.0;
        }
        let root_area = self.tlas.bounds().half_area_f64();
        let mut top = 0.0f64;
        for n in self.tlas.nodes() {
            top += n.bounds().half_area_f64() * f64::from(n.count.max(1));
        }
        let (mut weighted, mut total) = (0.0f64, 0.0f64);
        for (&k, b) in self.tlas_instances.iter().zip(&self.tlas_boxes) {
            let inst = &self.instances[k as usize];
            if !inst.visible {
                continue;
            }
            let m = &mut self.meshes[inst.mesh as usize];
            let w = b.half_area_f64() * f64::from(m.sah);
            m.world_area += b.half_area_f64();
            m.weight += w;
            total += w;
            weighted += w * f64::from(m.stats.sah_ratio);
        }
        if root_area > 0.0 {
            stats.sah = ((top + total) / root_area) as f32;
        }
        if total > 0.0 {
            stats.sah_ratio = (weighted / total) as f32;
        }
    }

    /// Gives each mesh's policy state its share of the last frame's trace cost from the
    /// ray-work sample: under [`CostMeasure::Rays`] by the mesh's own sampled work, under the
    /// SAH by its expected cost as [`Engine::record_trace`] splits it; the total is the
    /// sample's modelled estimate with [`Timing::Priced`], the recorded time otherwise.
    fn apply_sample(&mut self) {
        if self.sample.frame != self.frame || self.sample.sampled == 0 {
            return;
        }
        let p = self.config.prices;
        let scale = self.sample.scale();
        let modelled = scale * p.trace_ms(self.sample.work);
        let total = if self.config.timing == Timing::Priced {
            modelled
        } else {
            self.stats.trace_ms
        };
        self.frame_trace_ms = total;
        match self.config.cost {
            CostMeasure::Rays => {
                for (m, s) in self.meshes.iter_mut().zip(&self.mesh_samples) {
                    m.degradation.observe(s, &p, RAY_SMOOTHING);
                }
                for (m, s) in self.meshes.iter_mut().zip(&self.mesh_samples) {
                    let share = if modelled > 0.0 {
                        scale * p.trace_ms(s.work) / modelled
                    } else {
                        0.0
                    };
                    m.state.trace_share_ms = total * share;
                    m.state.traced_ratio = if m.stats.work_ratio > 0.0 {
                        m.stats.work_ratio
                    } else {
                        1.0
                    };
                }
            }
            CostMeasure::Sah => {
                let weights: f64 = self.meshes.iter().map(|m| m.weight).sum();
                if self.config.timing == Timing::Priced && weights > 0.0 {
                    for m in &mut self.meshes {
                        m.state.trace_share_ms = total * m.weight / weights;
                    }
                }
            }
        }
    }

    fn rebuild_tlas(&mut self) {
        self.tlas
            .rebuild(&self.tlas_boxes, &self.config.build, &mut self.workspace);
        self.tlas_build_sah = tree_sah(&self.tlas);
        self.tlas_stale = false;
    }

    /// Statistics of the last frame.
    #[must_use]
    pub fn frame_stats(&self) -> &FrameStats {
        &self.stats
    }

    /// What the last update did to `mesh`.
    #[must_use]
    pub fn mesh_stats(&self, mesh: MeshId) -> &MeshStats {
        &self.meshes[mesh.0 as usize].stats
    }

    /// Share of the expected trace cost that falls on `mesh`'s tree (its instances' world box
    /// areas times its SAH cost, over the sum of all): how the amortized policy splits a
    /// frame's trace time among meshes.
    #[must_use]
    pub fn mesh_trace_share(&self, mesh: MeshId) -> f64 {
        let total: f64 = self.meshes.iter().map(|m| m.weight).sum();
        if total > 0.0 {
            self.meshes[mesh.0 as usize].weight / total
        } else {
            0.0
        }
    }

    /// The binary tree of `mesh` (empty for a static mesh under [`Traversal::Wide`], which
    /// keeps only [`Engine::mesh_bvh8`]).
    #[must_use]
    pub fn mesh_bvh(&self, mesh: MeshId) -> &MeshBvh {
        &self.meshes[mesh.0 as usize].bvh
    }

    /// The 8-wide tree of `mesh` rays walk, with [`Traversal::Wide`].
    #[must_use]
    pub fn mesh_bvh8(&self, mesh: MeshId) -> Option<&MeshBvh8> {
        self.meshes[mesh.0 as usize].wide.as_ref()
    }

    /// The top-level tree; its primitive `p` is the `p`-th instance whose mesh has triangles.
    #[must_use]
    pub fn tlas(&self) -> &Bvh {
        &self.tlas
    }

    /// Box of the whole scene after the last update.
    #[must_use]
    pub fn bounds(&self) -> Aabb {
        self.tlas.bounds()
    }

    /// The box a camera should frame: the instances' triangle vertices in world space, less
    /// far outliers ([`crate::geom::framing_bounds`]), and how many vertex uses were left out.
    #[must_use]
    pub fn view_bounds(&self) -> (Aabb, u64) {
        crate::geom::framing_bounds(|f| {
            for inst in self.instances.iter().filter(|i| !i.removed) {
                let m = &self.meshes[inst.mesh as usize];
                for t in &m.indices {
                    for &v in t {
                        f(inst.transform.transform_point3(m.positions[v as usize]));
                    }
                }
            }
        })
    }

    /// The closest hit along `ray` in `[ray.tmin, ray.tmax)`.
    #[must_use]
    #[inline]
    pub fn closest_hit(&self, ray: &Ray) -> Option<SceneHit> {
        self.closest_impl(ray, &QueryFilter::ALL, &mut (), &mut ())
    }

    /// [`Engine::closest_hit`], adding nodes visited (both levels) and triangles tested to
    /// `stats`.
    pub fn closest_hit_counted(&self, ray: &Ray, stats: &mut TraversalStats) -> Option<SceneHit> {
        let mut top = TraversalStats::default();
        let hit = self.closest_impl(ray, &QueryFilter::ALL, stats, &mut top);
        stats.nodes += top.nodes;
        hit
    }

    #[inline]
    fn closest_impl(
        &self,
        ray: &Ray,
        filter: &QueryFilter,
        c: &mut impl Counters,
        top: &mut impl Counters,
    ) -> Option<SceneHit> {
        let prims = self.tlas.prim_indices();
        let mut best = None;
        self.tlas.closest_slot(
            ray,
            |slot, tmax| {
                let k = self.tlas_instances[prims[slot] as usize];
                let inst = &self.instances[k as usize];
                if !inst.visible || !filter.admits(k, inst.mask) {
                    return None;
                }
                let local = local_ray(inst, ray, tmax);
                let m = &self.meshes[inst.mesh as usize];
                let h = match &m.wide {
                    Some(w) => w.closest_hit_counted(&local, c),
                    None => m.bvh.closest_hit_counted(&local, c),
                }?;
                best = Some(SceneHit {
                    t: h.t,
                    u: h.u,
                    v: h.v,
                    prim: h.prim,
                    instance: InstanceId(k),
                });
                Some(h.t)
            },
            top,
        )?;
        best
    }

    /// True when anything is hit along `ray` in `[ray.tmin, ray.tmax)`.
    #[must_use]
    #[inline]
    pub fn any_hit(&self, ray: &Ray) -> bool {
        self.any_impl(ray, &QueryFilter::ALL, &mut (), &mut ())
    }

    /// [`Engine::any_hit`], adding nodes visited and triangles tested to `stats`.
    pub fn any_hit_counted(&self, ray: &Ray, stats: &mut TraversalStats) -> bool {
        let mut top = TraversalStats::default();
        let hit = self.any_impl(ray, &QueryFilter::ALL, stats, &mut top);
        stats.nodes += top.nodes;
        hit
    }

    #[inline]
    fn any_impl(
        &self,
        ray: &Ray,
        filter: &QueryFilter,
        c: &mut impl Counters,
        top: &mut impl Counters,
    ) -> bool {
        let prims = self.tlas.prim_indices();
        self.tlas
            .any_slot(
                ray,
                |slot, tmax| {
                    let k = self.tlas_instances[prims[slot] as usize];
                    let inst = &self.instances[k as usize];
                    if !inst.visible || !filter.admits(k, inst.mask) {
                        return None;
                    }
                    let local = local_ray(inst, ray, tmax);
                    let m = &self.meshes[inst.mesh as usize];
                    match &m.wide {
                        Some(w) => w.any_hit_counted(&local, c),
                        None => m.bvh.any_hit_counted(&local, c),
                    }
                    .then_some(0.0)
                },
                top,
            )
            .is_some()
    }

    /// What the SAH predicts a ray that hits the scene's box costs without early termination:
    /// `(nodes visited, triangles tested)`, over both levels (instance boxes in world space,
    /// instance trees by their own areas), counted on the trees rays walk: the 8-wide trees
    /// with [`Traversal::Wide`] ([`expected_work_wide`]), else the binary ones
    /// ([`expected_work`]), as [`Engine::closest_hit_counted`] counts. Allocates nothing.
    #[must_use]
    pub fn predicted_work(&self) -> (f64, f64) {
        let root = self.tlas.bounds().half_area_f64();
        if root <= 0.0 {
            return (0.0, 0.0);
        }
        let mut nodes: f64 = self
            .tlas
            .nodes()
            .iter()
            .map(|n| n.bounds().half_area_f64())
            .sum::<f64>()
            / root;
        let mut tris = 0.0;
        // Each mesh's tree once, weighted by its instances' world box areas (summed by the
        // last update).
        for m in self.meshes.iter().filter(|m| m.world_area > 0.0) {
            let (n, t) = match &m.wide {
                Some(w) => expected_work_wide(w),
                None => expected_work(m.bvh.bvh()),
            };
            let p = m.world_area / root;
            nodes += p * n;
            tris += p * t;
        }
        (nodes, tris)
    }
}

/// Share of a mesh's refit and trace time the fresh-build estimate may spend (so that it runs
/// only every few frames where the estimate costs about as much as a refit, e.g. small
/// meshes). Small enough that the estimate does not show in the total, large enough that the
/// decisions do not get worse (`docs/internals.md`, "Constants and the runs behind them").
const ESTIMATE_SHARE: f64 = 0.01;

/// Spare storage for a trial rebuild's wide tree: `w`'s capacities (its collapse left a
/// quarter of headroom), reserved and not written.
fn spare_wide(w: &MeshBvh8) -> MeshBvh8 {
    let mut spare = MeshBvh8::default();
    spare.reserve_like(w);
    spare
}

/// How much refitting the replaced tree alongside a new one may cost, as a share of the
/// rebuild's cost, before the probation ends undecided: with the whole rebuild cost, a failed
/// rebuild costs the mesh about twice what it set out to save.
const PROBE_SHARE: f64 = 0.5;

/// Weight of the past in the smoothed ray-work ratio (each frame's sample is a few hundred
/// rays: its mean is known to a few per cent).
const RAY_SMOOTHING: f64 = 0.5;

/// Rays per parallel task.
const RAY_CHUNK: usize = 256;

/// One frame of a probed rebuild, after `m`'s tree was refitted: refits the replaced tree too
/// and decides. Returns true when it went back to the replaced tree.
fn probe_step(m: &mut MeshEntry, mut p: Probe, timing: Timing, prices: &Prices) -> bool {
    let t = Instant::now();
    m.prev.refit_indexed(&m.positions, &m.indices);
    let old_sah = tree_sah(m.prev.bvh());
    p.cost_ms += timing.refit_ms(ms_since(t), m.indices.len(), prices);
    m.stats.model_ms += prices.refit_ms(m.indices.len());
    p.frames += 1;
    // What tracing this frame with the new tree gains (or would lose: then the old tree is
    // back before the trace, and the loss counts against the rebuild as a measure of how fast
    // the new tree degraded).
    p.saved_ms += m.state.trace_share_ms * f64::from(ratio(old_sah, m.sah) - 1.0);
    if old_sah < m.sah {
        go_back(m, &p, old_sah);
        return true;
    }
    probation_goes_on(m, p);
    false
}

/// SAH ratio of the tree in use to its build over its sampled degradation (ratio less 1)
/// from which a kept trial's replaced tree is compared with it ([`ray_probe_step`]): where
/// the SAH rises and the sampled ratio does not, the sample may be blind to the tree's
/// degradation (a lidar fan sweeping other parts of a cloth each frame, `docs/ray_work.md`);
/// where both rise (an explosion), the estimate is not in doubt.
const BACK_DISAGREEMENT: f64 = 0.15;

/// One frame of a kept trial's probation under the ray-work measure, after `m`'s tree was
/// refitted: at 1, 2, 4, .. frames after the rebuild, and only while the SAH ratio of the tree
/// in use to its build exceeds its sampled ratio by more than [`BACK_DISAGREEMENT`], the
/// replaced tree (and its wide tree) is refitted and both trees are replayed on the last
/// frame's sampled `entries`; the replaced one comes back when it costs them less. Returns
/// true when it went back (the wide trees swapped with the binary ones, both current).
fn ray_probe_step(
    m: &mut MeshEntry,
    id: MeshId,
    mut p: Probe,
    entries: &[SampleEntry],
    timing: Timing,
    prices: &Prices,
) -> bool {
    p.frames += 1;
    let doubt = f64::from(ratio(m.sah, m.state.build_sah)) - m.degradation.ratio().unwrap_or(1.0);
    if p.frames < p.next
        || doubt <= BACK_DISAGREEMENT
        || entries.is_empty()
        || m.wide.is_some() != m.prev_wide.is_some()
    {
        m.probe = Some(p);
        return false;
    }
    p.next = 2 * p.frames;
    let t = Instant::now();
    m.prev.refit_indexed(&m.positions, &m.indices);
    for w in [&mut m.prev_wide, &mut m.wide].into_iter().flatten() {
        w.refit_indexed(&m.positions, &m.indices);
    }
    let tris = m.indices.len();
    let refit_ms = timing.refit_ms(ms_since(t), tris, prices);
    let old = prices.trace_ms(sample::replay_work(
        &m.prev,
        m.prev_wide.as_ref(),
        id,
        entries,
    ));
    let new = prices.trace_ms(sample::replay_work(&m.bvh, m.wide.as_ref(), id, entries));
    m.stats.model_ms += prices.refit_ms(tris) + old + new;
    p.cost_ms += refit_ms + old + new;
    if new <= 0.0 {
        m.probe = Some(p);
        return false;
    }
    // Since the last comparison, as if each frame had gained as this one.
    p.saved_ms += m.state.trace_share_ms * (old / new - 1.0) * f64::from(p.frames - p.last);
    p.last = p.frames;
    if old < new {
        if let (Some(w), Some(spare)) = (&mut m.wide, &mut m.prev_wide) {
            std::mem::swap(w, spare);
        }
        let sah = tree_sah(m.prev.bvh());
        go_back(m, &p, sah);
        return true;
    }
    probation_goes_on(m, p);
    false
}

/// Back to the tree a rebuild on probation replaced (in `m.prev`, refitted to the frame, of
/// SAH cost `sah`): its build figures, age and degradation reference; what was learnt since
/// stays, and the extra trace time counts afresh.
fn go_back(m: &mut MeshEntry, p: &Probe, sah: f32) {
    std::mem::swap(&mut m.bvh, &mut m.prev);
    m.sah = sah;
    let learnt = m.state;
    m.state = PolicyState {
        since_build: p.state.since_build + p.frames,
        extra_ms: 0.0,
        ..p.state
    };
    m.state.rebuild_ms = learnt.rebuild_ms;
    m.state.trace_share_ms = learnt.trace_share_ms;
    m.state.traced_ratio = learnt.traced_ratio;
    m.state.estimate_gain = learnt.estimate_gain;
    m.state.rebuild_scale = learnt.rebuild_scale;
    m.state.ray_calibrations = learnt.ray_calibrations;
    m.degradation = p.degradation;
    // A rebuild that earned back less than half its cost before the old tree won was a
    // mistake to learn from (a tree built mid-way through a motion that swings back is soon
    // worse than the old one); one that earned more was worth about what it cost (a morph
    // that returns to where the old tree was built), and penalising those returns would keep
    // the mesh from the rebuilds it needs.
    if p.saved_ms < 0.5 * p.rebuild_ms {
        m.state.rebuild_failed();
    }
}

/// The new tree stays this frame: its rebuild has paid once it saved its cost; otherwise the
/// probation goes on while it has cost less than [`PROBE_SHARE`] of the rebuild.
fn probation_goes_on(m: &mut MeshEntry, p: Probe) {
    if p.saved_ms >= p.rebuild_ms {
        m.state.rebuild_paid();
    } else if p.cost_ms < PROBE_SHARE * p.rebuild_ms {
        m.probe = Some(p);
    }
}

fn set_transform(inst: &mut InstanceEntry, transform: Affine3A) {
    inst.transform = transform;
    inst.identity = transform == Affine3A::IDENTITY;
    let inverse = invert(&transform);
    inst.inverse = inverse.unwrap_or(Affine3A::IDENTITY);
    inst.visible = inverse.is_some();
    inst.dirty = true;
}

/// The inverse of `t`, or `None` when it has none in f32 (a zero or non-finite scale). Where
/// the determinant is a normal number the plain inverse; where it overflows or underflows
/// (a scale of 1e15 has a determinant of 1e45) the inverse of the matrix divided by its
/// largest entry, divided by that entry again.
fn invert(t: &Affine3A) -> Option<Affine3A> {
    let det = t.matrix3.determinant();
    let inv = if det.is_normal() {
        t.inverse()
    } else {
        let big = t
            .matrix3
            .abs()
            .to_cols_array()
            .into_iter()
            .fold(0.0f32, f32::max);
        if !(big > 0.0 && big.is_finite()) {
            return None;
        }
        let m = t.matrix3 * (1.0 / big);
        if !m.determinant().is_normal() {
            return None;
        }
        let linear = m.inverse() * (1.0 / big);
        Affine3A {
            matrix3: linear,
            translation: -(linear * t.translation),
        }
    };
    (inv.matrix3.is_finite() && inv.translation.is_finite()).then_some(inv)
}

/// The ray in the instance's space over `[ray.tmin, tmax)`; `t` keeps its meaning.
#[inline(always)]
fn local_ray(inst: &InstanceEntry, ray: &Ray, tmax: f32) -> Ray {
    if inst.identity {
        let mut r = *ray;
        r.tmax = tmax;
        r
    } else {
        Ray::with_range(
            inst.inverse.transform_point3(ray.origin),
            local_dir(&inst.inverse, ray.dir),
            ray.tmin,
            tmax,
        )
    }
}

/// `m`'s linear part applied to the direction `d`. Where `d` is not finite, a zero entry of
/// `m` times an infinite component counts as zero, as it does for the world-space ray (a
/// translated instance keeps the direction), instead of making every axis NaN.
fn local_dir(m: &Affine3A, d: Vec3) -> Vec3 {
    if d.is_finite() {
        return m.transform_vector3(d);
    }
    let cols = [m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis];
    let mut out = [0f32; 3];
    for (col, c) in cols.iter().zip(d.to_array()) {
        for (o, e) in out.iter_mut().zip(col.to_array()) {
            if e != 0.0 {
                *o += e * c;
            }
        }
    }
    Vec3::from(out)
}

/// The box of `b` transformed by `m` ([`Aabb::transformed`]).
fn transform_box(m: &Affine3A, b: Aabb) -> Aabb {
    b.transformed(m)
}

/// Expected nodes visited and triangles tested by a ray through the tree's root (no early
/// termination), as the binary traversal counts them: a node (interior or leaf) when the ray
/// hits its box, with probability its area over the root's (exact in expectation for uniformly
/// random lines through the root's box), and a leaf's triangles with it.
#[must_use]
pub fn expected_work(bvh: &Bvh) -> (f64, f64) {
    let nodes = bvh.nodes();
    let Some(root) = nodes.first() else {
        return (0.0, 0.0);
    };
    let a = root.bounds().half_area_f64();
    if a <= 0.0 {
        return (1.0, f64::from(root.count));
    }
    let (n, t) = nodes.iter().fold((0.0, 0.0), |(n, t), x: &Node| {
        let ar = x.bounds().half_area_f64();
        (n + ar, t + ar * f64::from(x.count))
    });
    (n / a, t / a)
}

/// [`expected_work`] for a wide tree, counted as its traversal counts
/// ([`WideBvh::closest_hit_counted`]): the root node always (the traversal starts there without
/// testing its box; the engine gets there through the instance's box), every other interior
/// node and every leaf lane when the ray hits the lane's box in the parent (probability: the
/// lane box's area over the root's), and a leaf lane's triangles (unused block lanes not
/// counted) with it.
#[must_use]
pub fn expected_work_wide<const K: usize>(w: &WideBvh<K>) -> (f64, f64) {
    let nodes = w.nodes();
    let Some(root) = nodes.first() else {
        return (0.0, 0.0);
    };
    let blocks = w.blocks();
    let a = root.bounds().half_area_f64();
    // Area sums over the children (interior and leaf lanes) and over leaf lanes times their
    // triangles; and the plain counts, for a root of no area.
    let (mut n, mut t, mut lanes, mut tris) = (0.0, 0.0, 0.0, 0.0);
    for node in nodes {
        for k in 0..K {
            let (count, area) = match node.child(k) {
                Child::Empty => continue,
                Child::Node(_) => (0.0, node.lane_bounds(k).half_area_f64()),
                Child::Leaf { first, count } => {
                    let run = &blocks[first as usize..(first + count) as usize];
                    let used = run.iter().flat_map(|b| b.prims).filter(|&p| p != NO_PRIM);
                    (used.count() as f64, node.lane_bounds(k).half_area_f64())
                }
            };
            n += area;
            t += area * count;
            lanes += 1.0;
            tris += count;
        }
    }
    if a > 0.0 && a.is_finite() {
        (1.0 + n / a, t / a)
    } else {
        (1.0 + lanes, tris)
    }
}

/// SAH cost of a tree (as [`Bvh::sah_cost`]), summed in parallel for large trees.
#[must_use]
pub fn tree_sah(bvh: &Bvh) -> f32 {
    let nodes = bvh.nodes();
    if nodes.len() < 1 << 16 {
        return bvh.sah_cost();
    }
    let a = nodes[0].bounds().half_area_f64();
    if !(a > 0.0 && a.is_finite()) {
        return bvh.sah_cost();
    }
    let sum: f64 = nodes
        .par_chunks(1 << 14)
        .map(|c| {
            c.iter()
                .map(|n| n.bounds().half_area_f64() * f64::from(n.count.max(1)))
                .sum::<f64>()
        })
        .sum();
    (sum / a) as f32
}

fn ratio(sah: f32, base: f32) -> f32 {
    if base > 0.0 && sah.is_finite() {
        sah / base
    } else {
        1.0
    }
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::shapes::bumpy_sphere;
    use crate::report::rays::random_rays;

    /// A static mesh is built in the engine's build workspace only where that already holds
    /// it, so the workspace (kept for rebuilds) stays sized for the meshes that deform; either
    /// way its 8-wide tree is the one `MeshBvh8::build` makes.
    #[test]
    fn a_static_mesh_does_not_grow_the_rebuild_workspace() {
        let (big, small) = (bumpy_sphere(20_000), bumpy_sphere(2_000));
        let mut e = Engine::new(EngineConfig::default());
        let a = e.add_static_mesh(big.positions.clone(), big.indices.clone());
        assert_eq!(e.workspace.memory_bytes(), 0, "grown by a static mesh");
        e.add_mesh(small.positions.clone(), small.indices.clone());
        let held = e.workspace.memory_bytes();
        assert!(held > 0, "an ordinary mesh builds in the workspace");
        let b = e.add_static_mesh(small.positions.clone(), small.indices.clone());
        let c = e.add_static_mesh(big.positions.clone(), big.indices.clone());
        assert_eq!(e.workspace.memory_bytes(), held, "grown by a static mesh");
        for (id, mesh) in [(a, &big), (b, &small), (c, &big)] {
            let kept = e.mesh_bvh8(id).expect("the wide tree");
            let fresh = MeshBvh8::build(mesh, &e.config.build);
            assert_eq!(kept.nodes().len(), fresh.nodes().len());
            for r in random_rays(&mesh.bounds(), 500, 7) {
                let hit = |w: &MeshBvh8| w.closest_hit(&r).map(|h| (h.t, h.prim));
                assert_eq!(hit(kept), hit(&fresh), "{id:?}: {r:?}");
            }
        }
    }
}
