//! Per-frame and per-mesh statistics the engine keeps (plain `Copy` data: recording them
//! allocates nothing).

use super::policy::Action;
use serde::Serialize;

/// What happened to one mesh in the last [`super::Engine::update`].
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct MeshStats {
    /// What was done to its tree.
    pub action: Action,
    /// Refit time (including measuring the SAH cost and estimating a fresh build's), ms.
    pub refit_ms: f64,
    /// Rebuild time, ms.
    pub rebuild_ms: f64,
    /// SAH cost of its tree now.
    pub sah: f32,
    /// `sah` over the cost right after the last (re)build.
    pub sah_ratio: f32,
    /// `sah` over the estimated cost of a fresh build now (see [`super::estimate`]); 0 when the
    /// policy does not estimate it.
    pub fresh_ratio: f32,
    /// Estimated ray-work degradation (sampled work over a fresh tree's) with
    /// [`super::CostMeasure::Rays`]: the SAH's estimated degradation scaled by how much of it
    /// the sampled rays felt at the last rebuilds; 0 with the SAH measure.
    pub work_ratio: f32,
    /// The ray-work ratio measured at this frame's rebuild: the replaced (refitted) tree's
    /// sampled work on the previous frame's rays over the new tree's; 0 when not measured.
    pub measured_work_ratio: f32,
    /// Modelled cost of this mesh's update (refit, rebuild, estimate, replayed samples) at the
    /// engine's prices, ms.
    pub model_ms: f64,
}

/// One frame as the engine saw it: update times, the trees' quality, and the traced rays.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct FrameStats {
    /// Frame number (updates since the engine was made).
    pub frame: u64,
    /// Time spent posing this frame (recorded by the caller with
    /// [`super::Engine::record_pose`] before the update), ms.
    pub pose_ms: f64,
    /// Refit time over all meshes, ms.
    pub refit_ms: f64,
    /// Rebuild time over all meshes, ms.
    pub rebuild_ms: f64,
    /// Time to update the instance boxes and the top-level tree, ms.
    pub tlas_ms: f64,
    /// `pose + refit + rebuild + tlas`, ms.
    pub update_ms: f64,
    /// Trace time recorded for this frame, ms.
    pub trace_ms: f64,
    /// Rays traced this frame.
    pub rays: u64,
    /// Millions of rays per second over `trace_ms`.
    pub mrays: f64,
    /// Refit (`Refit`), any rebuild (`Rebuild`), or no tree touched (`None`).
    pub action: Action,
    /// Meshes refitted.
    pub refits: u32,
    /// Meshes rebuilt.
    pub rebuilds: u32,
    /// Meshes optimised or partly rebuilt.
    pub restructures: u32,
    /// Meshes that went back to the tree their last rebuild replaced (it had become better
    /// again before the rebuild paid for itself).
    pub reverts: u32,
    /// Whether the top-level tree was rebuilt (else refitted, or untouched).
    pub tlas_rebuilt: bool,
    /// Expected cost of a ray that hits the scene's box: top-level nodes plus each instance's
    /// tree weighted by the chance a ray hits its box (SAH with both constants 1).
    pub sah: f32,
    /// Trace-weighted SAH ratio of the meshes (each mesh's ratio weighted by its share of the
    /// expected trace cost; static and rigid meshes count with ratio 1). The factor by which the
    /// SAH predicts this frame's tracing is slower than with freshly built trees.
    pub sah_ratio: f32,
    /// Largest SAH ratio of any deforming mesh.
    pub max_sah_ratio: f32,
    /// Largest estimated fresh ratio of any deforming mesh (0 when the policy does not
    /// estimate it).
    pub max_fresh_ratio: f32,
    /// SAH ratio of the top-level tree.
    pub tlas_sah_ratio: f32,
    /// Modelled cost of the meshes' updates at the engine's prices, ms.
    pub model_update_ms: f64,
    /// Modelled trace cost of the frame's rays: the ray-work sample's estimate of the frame's
    /// total work at the engine's prices, ms.
    pub model_trace_ms: f64,
    /// Modelled cost of the sample: what counting the sampled rays in the trace's own pass
    /// adds, or their whole work when they were traced again ([`super::Engine::sample_rays`]), ms.
    pub model_sample_ms: f64,
    /// Wall-clock time sampling added to the trace (measured in the pass), ms.
    pub sample_ms: f64,
    /// The ray-work sample's estimate of the mean work per ray.
    pub work: super::ray_work::WorkEstimate,
}
