//! The engine's side of the ray-work sample ([`crate::engine::ray_work`]): the sampled rays of
//! a batch are traced with counters in the batch's own pass (or again, for rays the caller
//! traced itself), each entry into an instance is kept with the work it cost, and the work is
//! added up per mesh.
//!
//! In a pass, each task keeps its sampled entries in a small buffer of its own and moves them
//! into the frame's log under a lock when it fills or the task ends: the log's order then
//! depends on the threads, but everything read from it is a sum of integers, the same in any
//! order.

use super::{Engine, RAY_CHUNK, SceneHit, local_ray};
use crate::bvh::{Counters, MeshBvh, MeshBvh8, TraversalStats};
use crate::engine::MeshId;
use crate::engine::policy::PolicyState;
use crate::engine::ray_work::{
    MeshSample, Query, RaySample, SampleEntry, SamplePlan, SampleSums, WorkEstimate, splitmix,
};
use crate::geom::{Hit, Ray};
use crate::parallel::Probe;
use rayon::prelude::*;
use std::sync::{Mutex, PoisonError};
use std::time::Instant;

/// What a recorded trace found and cost.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Traced {
    /// The closest hit (closest-hit queries).
    pub hit: Option<SceneHit>,
    /// Something was hit (both queries).
    pub blocked: bool,
    /// Work in both levels.
    pub work: TraversalStats,
    /// Work in the top-level tree.
    pub top: TraversalStats,
}

/// The frame's log of sampled entries while a pass runs.
#[derive(Default)]
struct SampleLog {
    entries: Vec<SampleEntry>,
    /// The entries' capacity when the pass began.
    capacity: usize,
    sums: SampleSums,
    clock: PassClock,
}

/// What a pass's sampling took beyond its trace: each task times its chunk's plain rays and,
/// after them, its sampled rays traced with counters back to back; a sampled ray's extra is its
/// time over the plain rays' mean (the sample is systematic, so the rays it takes cost the
/// mean plainly, in expectation). The sampling's own bookkeeping (the frame's plan, the task
/// buffers and the log, merging the entries into the meshes' samples) is extra in full.
/// Summed over the tasks and the pass's serial parts, with their whole time.
#[derive(Clone, Copy, Debug, Default)]
struct PassClock {
    recorded_ns: f64,
    recorded: u64,
    plain_ns: f64,
    plain: u64,
    /// The bookkeeping's time.
    overhead_ns: f64,
    pass_ns: f64,
}

impl PassClock {
    fn merge(&mut self, o: &Self) {
        self.recorded_ns += o.recorded_ns;
        self.recorded += o.recorded;
        self.plain_ns += o.plain_ns;
        self.plain += o.plain;
        self.overhead_ns += o.overhead_ns;
        self.pass_ns += o.pass_ns;
    }

    /// The share of the pass its sampling took.
    fn share(&self) -> f64 {
        if self.recorded == 0 || self.plain == 0 || self.pass_ns <= 0.0 {
            return 0.0;
        }
        let extra = self.recorded_ns - self.recorded as f64 * self.plain_ns / self.plain as f64
            + self.overhead_ns;
        (extra / self.pass_ns).max(0.0)
    }
}

/// Entries a task keeps before moving them into the log.
const BUF: usize = 32;

/// One task's sampled entries and work, moved into the shared log when full and when dropped.
struct TaskBuf<'a> {
    items: [Option<SampleEntry>; BUF],
    len: usize,
    sums: SampleSums,
    clock: PassClock,
    log: &'a Mutex<SampleLog>,
}

impl<'a> TaskBuf<'a> {
    fn new(log: &'a Mutex<SampleLog>) -> Self {
        Self {
            items: [None; BUF],
            len: 0,
            sums: SampleSums::default(),
            clock: PassClock::default(),
            log,
        }
    }

    fn push(&mut self, e: SampleEntry) {
        if self.len == BUF {
            self.flush();
        }
        self.items[self.len] = Some(e);
        self.len += 1;
    }

    fn flush(&mut self) {
        self.flush_since(None);
    }

    /// Moves the entries into the log; with `since`, the time from then until they are in is
    /// counted as the pass's bookkeeping.
    fn flush_since(&mut self, since: Option<Instant>) {
        let mut log = self.log.lock().unwrap_or_else(PoisonError::into_inner);
        log.entries.extend(self.items[..self.len].iter().flatten());
        log.sums.merge(&self.sums);
        if let Some(t) = since {
            let ns = t.elapsed().as_nanos() as f64;
            self.clock.overhead_ns += ns;
            self.clock.pass_ns += ns;
        }
        log.clock.merge(&self.clock);
        self.len = 0;
        self.sums = SampleSums::default();
        self.clock = PassClock::default();
    }
}

impl Drop for TaskBuf<'_> {
    fn drop(&mut self) {
        if self.len > 0 || self.sums.sampled() > 0 || self.clock.pass_ns > 0.0 {
            self.flush();
        }
    }
}

impl Engine {
    /// Takes this frame's share of `rays` into the ray-work sample by tracing the sampled ones
    /// again with counters: for rays the caller traced itself (the `&self` queries, packets,
    /// its own threads). The batch queries ([`Engine::trace_closest`], [`Engine::trace_any`])
    /// sample in their own pass instead. Call it with every batch a frame casts, after the
    /// trace or before (the trees are the same until the next update); the policy reads the
    /// sample at the next [`Engine::update`]. Allocates only to grow the entry log past the
    /// largest frame's sample so far.
    pub fn sample_rays(&mut self, rays: &[Ray], query: Query) {
        let Some(plan) = self.begin_sample(rays.len()) else {
            return;
        };
        let (before, log) = self.open_log();
        // Rays spanned by one task: about `RAY_CHUNK / 16` of them sampled.
        let span = RAY_CHUNK / 16 * plan.stride() as usize;
        let this = &*self;
        let task = |c: usize| {
            let mut buf = TaskBuf::new(&log);
            for j in plan.picks(c * span, (c + 1) * span) {
                let t = this.trace_recording(&rays[j], query, &mut |e| {
                    buf.push(e);
                });
                buf.sums.add(t.work, t.top);
            }
        };
        // The first task on the calling thread, timed: whether the rest is worth the pool
        // ([`crate::parallel`]).
        let tasks = rays.len().div_ceil(span);
        if Probe::timed(1, tasks, || task(0)).split() {
            (1..tasks).into_par_iter().for_each(task);
        } else {
            (1..tasks).for_each(task);
        }
        let log = log.into_inner().unwrap_or_else(PoisonError::into_inner);
        // Traced again in full: the sample costs its whole work.
        let model = self.config.prices.trace_ms(log.sums.work());
        self.close_log(log, before, model);
    }

    /// Closest hits of a batch in parallel, this frame's sample taken in the same pass (the
    /// sampled rays traced with counters, their entries kept). Returns the share of the pass's
    /// time the sampling took beyond tracing those rays plainly, its bookkeeping included
    /// ([`PassClock`]).
    pub(super) fn closest_sampled(&mut self, rays: &[Ray], out: &mut [Option<SceneHit>]) -> f64 {
        let batch = (Engine::closest_hit, Engine::closest_hit_batch);
        self.sampled_pass(rays, out, Query::Closest, batch, |t| t.hit)
    }

    /// Any-hit answers of a batch with the sample taken in the same pass (see
    /// [`Engine::closest_sampled`]).
    pub(super) fn any_sampled(&mut self, rays: &[Ray], out: &mut [bool]) -> f64 {
        let batch = (Engine::any_hit, Engine::any_hit_batch);
        self.sampled_pass(rays, out, Query::Any, batch, |t| t.blocked)
    }

    fn sampled_pass<O: Send>(
        &mut self,
        rays: &[Ray],
        out: &mut [O],
        query: Query,
        (plain, batch): (
            impl Fn(&Engine, &Ray) -> O + Sync,
            impl FnOnce(&Engine, &[Ray], &mut [O]),
        ),
        recorded: impl Fn(&Traced) -> O + Sync,
    ) -> f64 {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        let pass = Instant::now();
        // Nothing to sample (no mesh moved, or the batch ends before its first sampled ray):
        // the plain pass (reordered when the batch is incoherent).
        let Some(plan) = self.begin_sample(rays.len()).filter(|p| !p.is_empty()) else {
            batch(self, rays, out);
            return 0.0;
        };
        let (before, log) = self.open_log();
        let opened = Instant::now();
        let this = &*self;
        // The batch's first rays answered plainly on the calling thread, timed: whether the
        // rest is worth the pool ([`crate::parallel`]). The first chunk does not answer them
        // again (a sampled one among them is traced again, recorded).
        let probe = Probe::run(rays.len(), |i| out[i] = plain(this, &rays[i]));
        let probe_ns = probe.elapsed().as_nanos() as f64;
        // On the pool, chunks of up to sixteen times the plain pass's, while each thread still
        // gets four, and a small batch one chunk a thread: fewer task buffers to fill and
        // merge, and more sampled rays back to back in each. On the calling thread alone, one
        // chunk: one buffer, every sampled ray in one run.
        let split = probe.split();
        let threads = rayon::current_num_threads();
        let size = if !split {
            rays.len().max(1)
        } else if rays.len() <= 2 * threads * RAY_CHUNK {
            rays.len().div_ceil(threads)
        } else {
            (rays.len() / (4 * threads)).clamp(RAY_CHUNK, 16 * RAY_CHUNK)
        };
        let chunk_pass = |c: usize, o: &mut [O], chunk: &[Ray]| {
            let base = c * size;
            // The plain rays first, then the sampled ones back to back: a sampled ray's
            // longer walk then runs in code and branch history that are warm, not once
            // among every `stride` plain ones.
            let start = Instant::now();
            let picks = plan.picks(base, base + chunk.len()).map(|i| i - base);
            let mut buf = TaskBuf::new(&log);
            // The runs of rays between two skipped ones (sampled, or answered by the probe),
            // each in a loop of its own, with no test per ray.
            let mut skip = picks.clone();
            let mut next = skip.next().unwrap_or(usize::MAX);
            let mut taken = probe.taken(base, base + chunk.len());
            let mut next_taken = taken.next().map_or(usize::MAX, |i| i - base);
            let (mut from, mut plain_n) = (0, 0);
            while from < chunk.len() {
                let to = next.min(next_taken).min(chunk.len());
                for (o, r) in o[from..to].iter_mut().zip(&chunk[from..to]) {
                    *o = plain(this, r);
                }
                plain_n += (to - from) as u64;
                if next == to {
                    next = skip.next().unwrap_or(usize::MAX);
                }
                if next_taken == to {
                    next_taken = taken.next().map_or(usize::MAX, |i| i - base);
                }
                from = to + 1;
            }
            let mid = Instant::now();
            let mut recorded_n = 0;
            for j in picks {
                let t = this.trace_recording(&chunk[j], query, &mut |e| buf.push(e));
                buf.sums.add(t.work, t.top);
                o[j] = recorded(&t);
                recorded_n += 1;
            }
            let end = Instant::now();
            let plain_ns = (mid - start).as_nanos() as f64;
            let recorded_ns = (end - mid).as_nanos() as f64;
            buf.clock.merge(&PassClock {
                recorded_ns,
                recorded: recorded_n,
                plain_ns,
                plain: plain_n,
                overhead_ns: 0.0,
                pass_ns: plain_ns + recorded_ns,
            });
            buf.flush_since(Some(end));
        };
        crate::parallel::chunks(split, rays, out, size, chunk_pass);
        let closing = Instant::now();
        let log = log.into_inner().unwrap_or_else(PoisonError::into_inner);
        let mut clock = log.clock;
        let model = self.config.prices.sample_ms(log.sums.sampled());
        self.close_log(log, before, model);
        let closed = Instant::now();
        // The plan and the log before the probe, the merge after the tasks: bookkeeping.
        let serial = ((opened - pass) + (closed - closing)).as_nanos() as f64;
        clock.merge(&PassClock {
            plain_ns: probe_ns,
            plain: probe.count() as u64,
            overhead_ns: serial,
            pass_ns: probe_ns + serial,
            ..PassClock::default()
        });
        let share = clock.share();
        self.stats.sample_ms += share * (closed - pass).as_secs_f64() * 1e3;
        share
    }

    /// The frame's sample plan for a batch of `n` rays, starting a new sample at a new frame;
    /// `None` (nothing sampled) when no mesh of more than one leaf was refitted or rebuilt
    /// whose policy wants this frame's sample.
    fn begin_sample(&mut self, n: usize) -> Option<SamplePlan> {
        if !(self.config.always_sample || PolicyState::reads_sample(self.config.policy)) {
            return None;
        }
        if self.sample.frame != self.frame {
            // Nothing was refitted or rebuilt (or only trees of one leaf, which cannot
            // degrade), or no policy can act before a later sample
            // ([`crate::engine::watch`]): no policy has anything to weigh, unless a mesh was
            // added since the last sample (its fresh tree's work is the ray-work measure's
            // reference for its first refits). Once a frame's sample has begun, every batch of
            // the frame is sampled.
            if !self.unsampled_meshes
                && !self
                    .meshes
                    .iter()
                    .any(|m| m.moved && !m.one_leaf() && m.state.watch.due())
            {
                return None;
            }
            self.unsampled_meshes = false;
            self.sample = RaySample::after(self.frame, self.sample.rays);
            self.entries.clear();
            self.mesh_samples.fill(MeshSample::default());
            self.stats.model_sample_ms = 0.0;
        }
        Some(self.sample.plan(n))
    }

    /// The entry log for a pass (the engine's buffer, moved), and where its new entries start.
    fn open_log(&mut self) -> (usize, Mutex<SampleLog>) {
        let entries = std::mem::take(&mut self.entries);
        (
            entries.len(),
            Mutex::new(SampleLog {
                capacity: entries.capacity(),
                entries,
                ..SampleLog::default()
            }),
        )
    }

    /// Merges a pass's log (its entries from `before` on are new) into the frame's sample;
    /// `model_ms` is what the sampling cost at the prices.
    fn close_log(&mut self, log: SampleLog, before: usize, model_ms: f64) {
        let grew = log.entries.capacity() != log.capacity;
        self.entries = log.entries;
        let p = self.config.prices;
        for e in &self.entries[before..] {
            self.mesh_samples[e.mesh.0 as usize].add(e);
        }
        // Headroom once it has had to grow: later frames whose rays enter a few more instances
        // do not grow it again.
        if grew {
            self.entries.reserve_exact(self.entries.len());
        }
        self.sample.merge(&log.sums);
        self.stats.model_trace_ms = self.sample.scale() * p.trace_ms(self.sample.work);
        self.stats.model_sample_ms += model_ms;
        self.stats.work = self.sample.estimate();
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

    /// The ray-work sample of the frame traced since the last update (empty before any, and
    /// on a frame nothing was sampled in: under the ray-work measure `amortized` and the ladder
    /// sample only the frames on which they could act, [`crate::engine::watch`]).
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
        self.current(|e| e.mesh_samples[mesh.0 as usize].work)
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
        let m = &self.meshes[mesh.0 as usize];
        entries
            .par_chunks(1024)
            .map(|c| tree_work(&m.bvh, m.wide.as_ref(), mesh, c))
            .reduce(TraversalStats::default, |mut a, b| {
                a += b;
                a
            })
    }

    /// For the prices' calibration ([`crate::engine::Prices::calibrate`]): every ray of `rays`
    /// traced as a sampled ray is in the batch's pass (counters, box counts, its entries kept
    /// in `log`), or plainly.
    pub(crate) fn trace_as_sampled(
        &self,
        rays: &[Ray],
        recorded: bool,
        log: &mut Vec<SampleEntry>,
    ) {
        log.clear();
        for r in rays {
            if recorded {
                let t = self.trace_recording(r, Query::Closest, &mut |e| log.push(e));
                std::hint::black_box(t.work);
            } else {
                std::hint::black_box(self.closest_hit(r));
            }
        }
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
            let t = self.trace_recording(r, query, &mut |e| {
                per_mesh[e.mesh.0 as usize] += e.work;
                entries.push(e);
            });
            top += t.top;
        }
        (top, per_mesh)
    }

    /// One ray through the scene with counters, each entry into an instance handed to
    /// `record` with the work it cost there.
    pub(super) fn trace_recording(
        &self,
        ray: &Ray,
        query: Query,
        record: &mut impl FnMut(SampleEntry),
    ) -> Traced {
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
        let mut best = None;
        let mut test = |slot: usize, tmax: f32| {
            let k = tlas_instances[prims[slot] as usize];
            let inst = &instances[k as usize];
            if !inst.visible {
                return None;
            }
            let local = local_ray(inst, ray, tmax);
            let m = &meshes[inst.mesh as usize];
            // Box counts for closest-hit entries only: an any-hit entry has none to give.
            let (h, work, pierced) = match query {
                Query::Closest => {
                    let mut w = BoxCounter::new(&local);
                    let h = trace_counted(&m.bvh, m.wide.as_ref(), &local, query, &mut w);
                    (h, w.work, Some(w.before(h.map_or(local.tmax, |h| h.t))))
                }
                Query::Any => {
                    let mut w = TraversalStats::default();
                    let h = trace_counted(&m.bvh, m.wide.as_ref(), &local, query, &mut w);
                    (h, w, None)
                }
            };
            inner += work;
            record(SampleEntry {
                mesh: MeshId(inst.mesh),
                query,
                ray: local,
                work,
                hit: h.is_some(),
                pierced,
            });
            let h = h?;
            best = Some(SceneHit {
                t: h.t,
                u: h.u,
                v: h.v,
                prim: h.prim,
                instance: super::InstanceId(k),
            });
            Some(h.t)
        };
        let blocked = match query {
            Query::Closest => tlas.closest_slot(ray, &mut test, &mut top).is_some(),
            Query::Any => tlas.any_slot(ray, &mut test, &mut top).is_some(),
        };
        let mut work = inner;
        work += top;
        Traced {
            hit: if query == Query::Closest { best } else { None },
            blocked,
            work,
            top,
        }
    }
}

/// One query through a mesh's tree (the wide one when there is one), counted: the hit (one
/// at distance 0 for an any-hit ray that is blocked).
fn trace_counted(
    bvh: &MeshBvh,
    wide: Option<&MeshBvh8>,
    ray: &Ray,
    query: Query,
    w: &mut impl Counters,
) -> Option<Hit> {
    let blocked = Hit {
        t: 0.0,
        u: 0.0,
        v: 0.0,
        prim: 0,
    };
    match (query, wide) {
        (Query::Closest, Some(t)) => t.closest_hit_counted(ray, w),
        (Query::Closest, None) => bvh.closest_hit_counted(ray, w),
        (Query::Any, Some(t)) => t.any_hit_counted(ray, w).then_some(blocked),
        (Query::Any, None) => bvh.any_hit_counted(ray, w).then_some(blocked),
    }
}

/// Most entries of one mesh the policy's replays trace: a paired ratio of two trees on the same
/// entries needs no more, and the replays' cost then stops growing with the frame's ray count
/// (uncapped, it outgrows the rebuild it judges: `docs/ray_work.md`).
const REPLAY_MAX: usize = 1024;

/// [`tree_work`] on at most about [`REPLAY_MAX`] of `mesh`'s entries: all of them when there
/// are no more, else those whose ray falls in one residue of a hash of its bits, the same
/// entries whatever their order (the log's order depends on the pass's threads) and for every
/// tree they are replayed on.
pub(super) fn replay_work(
    bvh: &MeshBvh,
    wide: Option<&MeshBvh8>,
    mesh: MeshId,
    entries: &[SampleEntry],
) -> TraversalStats {
    let n = entries.iter().filter(|e| e.mesh == mesh).count();
    let keep = n.div_ceil(REPLAY_MAX).max(1) as u64;
    let mut w = TraversalStats::default();
    for e in entries.iter().filter(|e| e.mesh == mesh) {
        if keep == 1 || ray_key(&e.ray).is_multiple_of(keep) {
            let _ = trace_counted(bvh, wide, &e.ray, e.query, &mut w);
        }
    }
    w
}

/// A hash of a ray's origin, direction and interval bits.
fn ray_key(r: &Ray) -> u64 {
    let [ox, oy, oz] = r.origin.to_array().map(f32::to_bits);
    let [dx, dy, dz] = r.dir.to_array().map(f32::to_bits);
    let word = |a: u32, b: u32| u64::from(a) << 32 | u64::from(b);
    let h = splitmix(word(ox, oy) ^ splitmix(word(oz, dx) ^ splitmix(word(dy, dz))));
    splitmix(h ^ u64::from(r.tmin.to_bits()))
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

/// A sampled ray's counters: its work, and the entry distances of the triangle boxes it meets
/// among the triangles it tests. An exact closest-hit walk tests every triangle whose box its
/// interval meets before the final hit (no leaf holding one can be passed over), so those
/// before the hit are the boxes the ray pierces there, whatever the tree
/// ([`Pierced`](crate::engine::ray_work::Pierced)).
struct BoxCounter {
    work: TraversalStats,
    ray: Ray,
    entries: [f32; BOX_ENTRIES],
    len: usize,
}

/// Box entry distances a sampled ray keeps (the count is capped there).
const BOX_ENTRIES: usize = 64;

impl BoxCounter {
    fn new(ray: &Ray) -> Self {
        Self {
            work: TraversalStats::default(),
            ray: *ray,
            entries: [0.0; BOX_ENTRIES],
            len: 0,
        }
    }

    /// The boxes met before `t`.
    fn before(&self, t: f32) -> u32 {
        self.entries[..self.len].iter().filter(|&&e| e <= t).count() as u32
    }
}

impl Counters for BoxCounter {
    #[inline(always)]
    fn node(&mut self) {
        self.work.node();
    }
    #[inline(always)]
    fn prim(&mut self) {
        self.work.prim();
    }
    const TRIANGLES: bool = true;
    #[inline(always)]
    fn triangle(&mut self, [a, b, c]: [glam::Vec3; 3], tmax: f32) {
        if self.len < BOX_ENTRIES
            && let Some(t) = self.ray.hit_box(a.min(b).min(c), a.max(b).max(c), tmax)
        {
            self.entries[self.len] = t;
            self.len += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::BuildParams;
    use crate::geom::shapes;
    use glam::Vec3;

    /// Entries of rays from a ring around a sphere towards points near its centre.
    fn entries(n: usize, mesh: u32) -> Vec<SampleEntry> {
        (0..n)
            .map(|i| {
                let a = i as f32 * 0.618;
                let o = Vec3::new(3.0 * a.cos(), 3.0 * a.sin(), (i % 7) as f32 * 0.1);
                let target = Vec3::new((i % 5) as f32 * 0.1, (i % 3) as f32 * 0.1, 0.0);
                SampleEntry {
                    mesh: MeshId(mesh),
                    query: Query::Closest,
                    ray: Ray::new(o, target - o),
                    work: TraversalStats::default(),
                    hit: false,
                    pierced: None,
                }
            })
            .collect()
    }

    #[test]
    fn replays_take_every_entry_up_to_the_cap_and_a_fixed_share_beyond_it() {
        let bvh = MeshBvh::build(&shapes::icosphere(3), &BuildParams::BINNED);
        let wide = MeshBvh8::from_mesh_bvh(&bvh);
        let (id, other) = (MeshId(1), 2);
        // Up to the cap: every entry of the mesh, the other mesh's left out.
        let mut few = entries(REPLAY_MAX, id.0);
        few.extend(entries(50, other));
        assert_eq!(
            replay_work(&bvh, Some(&wide), id, &few),
            tree_work(&bvh, Some(&wide), id, &few)
        );
        // Beyond it: about the cap's worth, the same entries in any order.
        let many = entries(8 * REPLAY_MAX, id.0);
        let part = replay_work(&bvh, Some(&wide), id, &many);
        let mut reversed = many.clone();
        reversed.reverse();
        assert_eq!(part, replay_work(&bvh, Some(&wide), id, &reversed));
        let all = tree_work(&bvh, Some(&wide), id, &many);
        let share = (part.nodes + part.prims) as f64 / (all.nodes + all.prims) as f64;
        assert!((0.08..0.17).contains(&share), "{share}");
    }

    #[test]
    fn a_pass_share_counts_the_sampled_rays_extra_and_the_bookkeeping() {
        // 992 plain rays at 30 ns, 8 sampled at 80 ns: 400 ns over their plain cost.
        let mut c = PassClock {
            recorded_ns: 640.0,
            recorded: 8,
            plain_ns: 29_760.0,
            plain: 992,
            overhead_ns: 0.0,
            pass_ns: 30_400.0,
        };
        assert!((c.share() - 400.0 / 30_400.0).abs() < 1e-12);
        // 600 ns of plan, buffers and merge on top, in the pass's time too.
        c.merge(&PassClock {
            overhead_ns: 600.0,
            pass_ns: 600.0,
            ..PassClock::default()
        });
        assert!((c.share() - 1_000.0 / 31_000.0).abs() < 1e-12);
        // No sampled ray: nothing to weigh.
        c.recorded = 0;
        assert_eq!(c.share(), 0.0);
    }
}
