//! Batches of rays through the engine, each of which feeds the refit-or-rebuild policy: its
//! wall-clock time is recorded as the frame's trace time ([`Engine::record_trace`]) and one ray
//! in [`crate::engine::ray_work::SAMPLE_STRIDE`] (at most about
//! [`crate::engine::ray_work::SAMPLE_MAX`] a frame) is taken into the ray-work sample in the same
//! pass, so that a caller who only casts batches gets the same decisions as the frame loop of
//! the benchmarks. The `&self` forms (`*_batch`) trace the same rays without telling the
//! policy, for callers that price their trace themselves or cast from several threads at once.
//! Large incoherent batches are traced in the order [`crate::bvh::ray_order`] plans (rays that
//! travel close together one after the other), except in a pass that takes the frame's
//! sample, whose picks follow the batch's own order.

use super::{Engine, SceneHit, ms_since};
use crate::bvh::MAX_PACKET;
use crate::bvh::ray_order::{RayOrder, as_they_come};
use crate::engine::ray_work::Query;
use crate::geom::Ray;
use crate::parallel::Probe;
use std::time::Instant;

/// A query answering a run of rays on the engine.
type Answers<T> = fn(&Engine, &[Ray], &mut [T]);

/// Rays per parallel task of the packet batches (whole packets).
const PACKET_CHUNK: usize = 8 * MAX_PACKET;

impl Engine {
    /// Closest hits of many rays, in parallel (`out[i]` for `rays[i]`), recorded as this
    /// frame's trace: timed into [`Engine::record_trace`] and sampled into the ray-work measure
    /// ([`Engine::sample_rays`]). Call it any number of times between two updates; the times
    /// add up. Returns the trace time in ms (sampling excluded).
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn trace_closest(&mut self, rays: &[Ray], out: &mut [Option<SceneHit>]) -> f64 {
        let t = Instant::now();
        self.closest_hit_batch_sampled(rays, out);
        self.traced_in_pass(ms_since(t), rays)
    }

    /// Any-hit answers of many rays, in parallel, recorded as this frame's trace as
    /// [`Engine::trace_closest`] records. Returns the trace time in ms.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn trace_any(&mut self, rays: &[Ray], out: &mut [bool]) -> f64 {
        let t = Instant::now();
        self.any_sampled(rays, out);
        self.traced_in_pass(ms_since(t), rays)
    }

    /// Closest hits of many rays, in parallel, with this frame's share of them taken into the
    /// ray-work sample in the same pass (as [`Engine::trace_closest`] does), but without
    /// recording the trace time: for callers that time their trace themselves (then call
    /// [`Engine::record_trace`]). Returns the share of the pass's time the sampling took
    /// beyond tracing those rays plainly, its bookkeeping included (from the pass's own
    /// clocks); that time is added to the frame's `sample_ms`.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn closest_hit_batch_sampled(&mut self, rays: &[Ray], out: &mut [Option<SceneHit>]) -> f64 {
        self.closest_sampled(rays, out)
    }

    /// The same as [`Engine::trace_closest`] (kept for the frame loops written against it).
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn trace_frame(&mut self, rays: &[Ray], out: &mut [Option<SceneHit>]) -> f64 {
        self.trace_closest(rays, out)
    }

    /// The same as [`Engine::trace_any`].
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn trace_frame_any(&mut self, rays: &[Ray], out: &mut [bool]) -> f64 {
        self.trace_any(rays, out)
    }

    /// Closest hits as packets ([`Engine::closest_hit_packet`] on runs of consecutive rays, the
    /// runs in parallel), recorded as this frame's trace as [`Engine::trace_closest`] records.
    /// Give coherent rays next to each other; a large batch whose neighbours are not is traced
    /// ray by ray in the order [`crate::bvh::ray_order`] plans. Returns the trace time in ms.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn trace_closest_packets(&mut self, rays: &[Ray], out: &mut [Option<SceneHit>]) -> f64 {
        self.packets_pass(
            rays,
            out,
            Query::Closest,
            (Engine::closest_hit_batch, Engine::closest_hit_packet),
        )
    }

    /// Any-hit answers as packets, recorded as this frame's trace (see
    /// [`Engine::trace_closest_packets`]). Returns the trace time in ms.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn trace_any_packets(&mut self, rays: &[Ray], out: &mut [bool]) -> f64 {
        self.packets_pass(
            rays,
            out,
            Query::Any,
            (Engine::any_hit_batch, Engine::any_hit_packet),
        )
    }

    /// Closest hits as packets, as [`Engine::trace_closest_packets`] traces them, without
    /// telling the policy (for callers that time and sample their trace themselves:
    /// [`Engine::record_trace`], [`Engine::sample_rays`]).
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn closest_hit_packets(&self, rays: &[Ray], out: &mut [Option<SceneHit>]) {
        self.packets_batch(
            rays,
            out,
            (Engine::closest_hit_batch, Engine::closest_hit_packet),
        );
    }

    /// The packets' frame pass of either query ([`Engine::packets_batch`]), recorded and
    /// sampled as this frame's trace.
    fn packets_pass<T: Send>(
        &mut self,
        rays: &[Ray],
        out: &mut [T],
        query: Query,
        answers: (Answers<T>, Answers<T>),
    ) -> f64 {
        let t = Instant::now();
        self.packets_batch(rays, out, answers);
        self.traced(ms_since(t), rays, query)
    }

    /// `packet` on runs of consecutive rays, in parallel when that pays, or `batch` (single
    /// rays in the planned order) for a batch none of whose packets would be coherent.
    fn packets_batch<T: Send>(
        &self,
        rays: &[Ray],
        out: &mut [T],
        (batch, packet): (Answers<T>, Answers<T>),
    ) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        if RayOrder::reordered(rays, &self.bounds()) {
            batch(self, rays, out);
        } else {
            // The packet in the middle of the batch (the first rays of an image are often
            // its empty corner) on the calling thread, timed: whether the rest is worth the
            // pool ([`crate::parallel`]). Chunks are whole packets, so the rest's pieces are.
            let at = rays.len() / 2 / MAX_PACKET * MAX_PACKET;
            let end = (at + MAX_PACKET).min(rays.len());
            let probe = Probe::timed(end - at, rays.len(), || {
                packet(self, &rays[at..end], &mut out[at..end]);
            });
            let chunk = |c: usize, o: &mut [T], r: &[Ray]| {
                let base = c * PACKET_CHUNK;
                if (base..base + r.len()).contains(&at) {
                    let (lo, hi) = (at - base, end - base);
                    packet(self, &r[..lo], &mut o[..lo]);
                    packet(self, &r[hi..], &mut o[hi..]);
                } else {
                    packet(self, r, o);
                }
            };
            crate::parallel::chunks(probe.split(), rays, out, PACKET_CHUNK, chunk);
        }
    }

    /// A frame scope for the single-ray and packet queries (`&self`): runs `f` on the engine
    /// and records its wall-clock time as this frame's trace time ([`Engine::record_trace`],
    /// with no ray count and no ray-work sample: under the default ray-work measure the policy
    /// then weighs the trees by their SAH ratio). Put all of a frame's casting in it, and
    /// nothing else: whatever `f` spends counts as tracing.
    pub fn trace_scope<R>(&mut self, f: impl FnOnce(&Engine) -> R) -> R {
        let t = Instant::now();
        let r = f(self);
        self.record_trace(ms_since(t), 0);
        r
    }

    /// Closest hits of many rays, in parallel: `out[i]` for `rays[i]`. Does not tell the
    /// policy (see [`Engine::trace_closest`], which does).
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn closest_hit_batch(&self, rays: &[Ray], out: &mut [Option<SceneHit>]) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        let answer = |r: &Ray| self.closest_hit(r);
        if let Ok(mut order) = self.order.try_lock() {
            order.run(rays, &self.bounds(), out, answer);
        } else {
            as_they_come(rays, out, answer);
        }
    }

    /// Any-hit answers of many rays, in parallel. Does not tell the policy (see
    /// [`Engine::trace_any`], which does).
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn any_hit_batch(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        let answer = |r: &Ray| self.any_hit(r);
        if let Ok(mut order) = self.order.try_lock() {
            order.run(rays, &self.bounds(), out, answer);
        } else {
            as_they_come(rays, out, answer);
        }
    }

    /// [`Engine::sample_rays`], its wall-clock time added to the frame's `sample_ms`.
    pub fn sample_timed(&mut self, rays: &[Ray], query: Query) {
        let t = Instant::now();
        self.sample_rays(rays, query);
        self.stats.sample_ms += ms_since(t);
    }

    /// Records a batch traced in `ms` and samples it again; returns `ms`.
    fn traced(&mut self, ms: f64, rays: &[Ray], query: Query) -> f64 {
        self.record_trace(ms, rays.len() as u64);
        self.sample_timed(rays, query);
        ms
    }

    /// Records a batch traced in `ms` that was sampled in its own pass; returns `ms`.
    fn traced_in_pass(&mut self, ms: f64, rays: &[Ray]) -> f64 {
        self.record_trace(ms, rays.len() as u64);
        ms
    }
}
