//! The engine's side of the ray-work sample ([`crate::engine::ray_work`]): the sampled rays are
//! traced again through the same trees with counters, each entry into an instance is kept, and
//! the work is added up per mesh.

use super::{Engine, local_ray};
use crate::bvh::{MeshBvh, MeshBvh8, TraversalStats};
use crate::engine::MeshId;
use crate::engine::ray_work::{Query, RaySample, SampleEntry, WorkEstimate};
use crate::geom::Ray;

impl Engine {
    /// Takes this frame's share of `rays` into the ray-work sample (call it with every batch a
    /// frame casts, after the trace or before: the trees are the same until the next update):
    /// every [`crate::engine::ray_work::SAMPLE_STRIDE`]-th ray is traced again with counters.
    /// [`Engine::trace_frame`] and [`Engine::trace_frame_any`] call it. The policy reads the
    /// sample at the next [`Engine::update`]. Allocates only to grow the entry buffer past the
    /// largest frame's sample so far.
    pub fn sample_rays(&mut self, rays: &[Ray], query: Query) {
        // Nothing was refitted or rebuilt: no policy has anything to weigh.
        if !self.meshes.iter().any(|m| m.moved) {
            return;
        }
        if self.sample.frame != self.frame {
            self.sample = RaySample::new(self.frame);
            self.entries.clear();
            self.sample_work.fill(TraversalStats::default());
            self.sample_entries.fill(0);
        }
        let mut sample = self.sample;
        let capacity = self.entries.capacity();
        for i in sample.take(rays.len()) {
            let (work, top) = self.sample_one(&rays[i], query);
            sample.add(work, top);
        }
        self.sample = sample;
        // When it had to grow, headroom: later frames whose rays enter a few more instances do
        // not grow it again.
        if self.entries.capacity() != capacity {
            self.entries.reserve_exact(self.entries.len());
        }
        let p = &self.config.prices;
        self.stats.model_trace_ms = sample.scale() * p.trace_ms(sample.work);
        self.stats.model_sample_ms = p.trace_ms(sample.work);
        self.stats.work = sample.estimate();
    }

    /// True when the sample belongs to the frame traced since the last update.
    fn sample_is_current(&self) -> bool {
        self.sample.frame == self.frame
    }

    /// `f` of the current frame's sample, or the default before any ray of it was sampled.
    fn current<T: Default>(&self, f: impl FnOnce(&Self) -> T) -> T {
        if self.sample_is_current() {
            f(self)
        } else {
            T::default()
        }
    }

    /// The ray-work sample of the frame traced since the last update (empty before any).
    #[must_use]
    pub fn work_estimate(&self) -> WorkEstimate {
        self.current(|e| e.sample.estimate())
    }

    /// Every entry of this frame's sampled rays into an instance (empty before any ray of the
    /// frame was sampled).
    #[must_use]
    pub fn sampled_entries(&self) -> &[SampleEntry] {
        if self.sample_is_current() {
            &self.entries
        } else {
            &[]
        }
    }

    /// Sampled work this frame in `mesh`'s tree (all its instances).
    #[must_use]
    pub fn sampled_mesh_work(&self, mesh: MeshId) -> TraversalStats {
        self.current(|e| e.sample_work[mesh.0 as usize])
    }

    /// Sampled work this frame, both levels.
    #[must_use]
    pub fn sampled_work(&self) -> TraversalStats {
        self.current(|e| e.sample.work)
    }

    /// Sampled work this frame in the top-level tree.
    #[must_use]
    pub fn sampled_top_work(&self) -> TraversalStats {
        self.current(|e| e.sample.top)
    }

    /// The work `mesh`'s current tree (the one rays walk) costs on `entries` (those of other
    /// meshes are skipped): how another engine's sample is replayed on this engine's tree. In
    /// parallel for long lists (the sum is the same in any order).
    #[must_use]
    pub fn mesh_work_on(&self, mesh: MeshId, entries: &[SampleEntry]) -> TraversalStats {
        use rayon::prelude::*;
        let m = &self.meshes[mesh.0 as usize];
        entries
            .par_chunks(1024)
            .map(|c| tree_work(&m.bvh, m.wide.as_ref(), mesh, c))
            .reduce(TraversalStats::default, |mut a, b| {
                a += b;
                a
            })
    }

    /// Traces every `stride`-th ray of `rays` from `offset` again with counters (a sample of the
    /// caller's own, e.g. a benchmark's denser one), appending each entry into an instance to
    /// `entries`; returns the work in the top-level tree and in each mesh's tree.
    pub fn trace_sampled(
        &self,
        rays: &[Ray],
        query: Query,
        stride: usize,
        offset: usize,
        entries: &mut Vec<SampleEntry>,
    ) -> (TraversalStats, Vec<TraversalStats>) {
        let mut per_mesh = vec![TraversalStats::default(); self.meshes.len()];
        let mut top = TraversalStats::default();
        for r in rays.iter().skip(offset).step_by(stride.max(1)) {
            let (_, t) = self.trace_recording(r, query, entries, &mut per_mesh);
            top += t;
        }
        (top, per_mesh)
    }

    /// Traces one sampled ray with counters, keeping its entries: `(all work, top-level work)`.
    fn sample_one(&mut self, ray: &Ray, query: Query) -> (TraversalStats, TraversalStats) {
        let mut entries = std::mem::take(&mut self.entries);
        let mut work = std::mem::take(&mut self.sample_work);
        let before = entries.len();
        let out = self.trace_recording(ray, query, &mut entries, &mut work);
        for e in &entries[before..] {
            self.sample_entries[e.mesh.0 as usize] += 1;
        }
        self.entries = entries;
        self.sample_work = work;
        out
    }

    /// One ray through the scene with counters: each instance entry appended to `entries`, each
    /// mesh's work added to `per_mesh`; returns `(all work, top-level work)`.
    fn trace_recording(
        &self,
        ray: &Ray,
        query: Query,
        entries: &mut Vec<SampleEntry>,
        sample_work: &mut [TraversalStats],
    ) -> (TraversalStats, TraversalStats) {
        let Engine {
            tlas,
            tlas_instances,
            instances,
            meshes,
            ..
        } = self;
        let prims = tlas.prim_indices();
        let mut inner = TraversalStats::default();
        let mut top = TraversalStats::default();
        let mut test = |slot: usize, tmax: f32| {
            let k = tlas_instances[prims[slot] as usize];
            let inst = &instances[k as usize];
            if !inst.visible {
                return None;
            }
            let local = local_ray(inst, ray, tmax);
            let m = &meshes[inst.mesh as usize];
            let mut w = TraversalStats::default();
            let t = trace_counted(&m.bvh, m.wide.as_ref(), &local, query, &mut w);
            sample_work[inst.mesh as usize] += w;
            inner += w;
            entries.push(SampleEntry {
                mesh: MeshId(inst.mesh),
                query,
                ray: local,
            });
            t
        };
        match query {
            Query::Closest => {
                let _ = tlas.closest_slot(ray, &mut test, &mut top);
            }
            Query::Any => {
                let _ = tlas.any_slot(ray, &mut test, &mut top);
            }
        }
        let mut all = inner;
        all += top;
        (all, top)
    }
}

/// One query through a mesh's tree (the wide one when there is one), counted: the hit distance
/// (0 for an any-hit ray that is blocked).
fn trace_counted(
    bvh: &MeshBvh,
    wide: Option<&MeshBvh8>,
    ray: &Ray,
    query: Query,
    w: &mut TraversalStats,
) -> Option<f32> {
    match (query, wide) {
        (Query::Closest, Some(t)) => t.closest_hit_counted(ray, w).map(|h| h.t),
        (Query::Closest, None) => bvh.closest_hit_counted(ray, w).map(|h| h.t),
        (Query::Any, Some(t)) => t.any_hit_counted(ray, w).then_some(0.0),
        (Query::Any, None) => bvh.any_hit_counted(ray, w).then_some(0.0),
    }
}

/// The work a mesh's tree costs on the entries of `mesh` among `entries`.
pub(super) fn tree_work(
    bvh: &MeshBvh,
    wide: Option<&MeshBvh8>,
    mesh: MeshId,
    entries: &[SampleEntry],
) -> TraversalStats {
    let mut w = TraversalStats::default();
    for e in entries.iter().filter(|e| e.mesh == mesh) {
        let _ = trace_counted(bvh, wide, &e.ray, e.query, &mut w);
    }
    w
}
