//! One deforming mesh's part of [`Engine::update`](super::Engine::update): refit, measure,
//! let the policy decide, act (rebuild, optimise, partial rebuild), and bring the wide tree
//! along. What the policy weighs is in [`crate::engine::policy`]; this file only runs it.

use super::background::Background;
use super::{
    ESTIMATE_SHARE, MeshEntry, Probe, Timing, ms_since, probe_step, ratio, ray_probe_step, sample,
};
use crate::bvh::optimize::{OptimizeBudget, OptimizeScratch};
pub(super) use crate::bvh::partial::PartialCut;
use crate::bvh::partial::PartialScratch;
use crate::bvh::topology::RestructureWorkspace;
use crate::bvh::{BuildParams, BuildWorkspace, TraversalStats};
use crate::engine::MeshId;
use crate::engine::policy::{Action, Decision, LADDER_OPTIMIZE, LADDER_PARTIAL, Policy};
use crate::engine::prices::Prices;
use crate::engine::ray_work::SampleEntry;
use std::time::Instant;

/// Scratch of the intermediate rungs, shared by every mesh.
#[derive(Clone, Debug, Default)]
pub(super) struct Restructure {
    pub ws: RestructureWorkspace,
    pub optimize: OptimizeScratch,
    pub partial: PartialScratch,
}

impl Restructure {
    /// Grows every buffer to what optimising and partly rebuilding `tree` can need (by
    /// running both once on a copy, and reserving what depends on the search), so that the
    /// frame loop allocates nothing for them.
    pub fn warm_up(&mut self, tree: &crate::bvh::MeshBvh, build: &BuildParams) {
        let mut t = tree.clone();
        let budget = OptimizeBudget {
            share: 1.0,
            ..OptimizeBudget::default()
        };
        self.optimize.reserve(budget);
        t.optimize(budget, &mut self.ws, &mut self.optimize);
        let mut t = tree.clone();
        let mut cut = PartialCut::default();
        cut.reset(&t, &mut self.partial);
        cut.mark_all_degraded();
        t.partial_rebuild(&mut cut, 1.0, build, &mut self.ws, &mut self.partial);
        self.ws.reserve(tree.bvh().prim_count());
    }
}

/// What a frame's update of every mesh shares.
pub(super) struct FrameContext<'a> {
    pub policy: Policy,
    pub build: BuildParams,
    pub timing: Timing,
    pub prices: Prices,
    /// The SAH measure's fresh-build estimate is wanted.
    pub estimate: bool,
    /// The policy weighs the ray-work ratio.
    pub ray_judged: bool,
    /// Rebuilds are probed (the replaced tree kept and refitted alongside).
    pub probes: bool,
    /// Rebuilds after a refit are trials, undone when the replay finds the new tree worse.
    pub trials: bool,
    /// The policy rebuilds into a spare tree (probes or trials, even on frames whose
    /// schedule is forced).
    pub spare: bool,
    /// The previous frame's sampled entries, replayed on the trees an action replaces and
    /// makes; empty when there is no sample of the previous frame or the SAH measures.
    pub entries: &'a [SampleEntry],
    /// The previous frame was sampled: the policy decides on a fresh sample.
    pub sampled: bool,
    /// Frames the policy's action cannot become due on go unsampled
    /// ([`crate::engine::watch`]).
    pub watched: bool,
    pub workspace: &'a mut BuildWorkspace,
    pub restructure: &'a mut Restructure,
    pub background: &'a mut Background,
    /// The frame being updated, and the last sampled frame's trace cost (ms).
    pub frame: u64,
    pub frame_trace_ms: f64,
    /// Updates the run still makes, this one included, when it is known.
    pub frames_left: Option<u64>,
    /// The action every mesh takes this frame whatever its policy says
    /// ([`super::Engine::force_next`]).
    pub forced: Option<Decision>,
}

/// What one mesh's update did, for the frame's statistics.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct MeshOutcome {
    pub reverted: bool,
    /// A background rebuild's tree was swapped in (a rebuild, whatever else the frame did).
    pub swapped: bool,
}

impl MeshEntry {
    /// True when the mesh's policy will want a partial rebuild's cut.
    pub(super) fn wants_cut(policy: Policy) -> bool {
        matches!(policy, Policy::Partial(_) | Policy::Ladder)
    }

    /// True when the mesh's tree is one leaf (or empty): its refit is then the tree a rebuild
    /// would make, so nothing can degrade and there is nothing to measure or decide.
    pub(super) fn one_leaf(&self) -> bool {
        self.bvh.bvh().nodes().len() <= 1
    }

    /// The pipeline for a mesh whose vertices moved.
    pub(super) fn update(&mut self, id: MeshId, cx: &mut FrameContext<'_>) -> MeshOutcome {
        if !self.any_shape {
            // A rebuild at another pose can have more nodes than the first build's tree (up to
            // 2n - 1): room for any, once, at the mesh's first frame as a deforming mesh, not
            // for meshes that never move. The spare a rebuild may go into gets the same.
            self.bvh.reserve_any_shape();
            if cx.spare {
                self.prev.reserve_like(&self.bvh);
            }
            self.any_shape = true;
        }
        let mut out = MeshOutcome::default();
        self.stats.model_ms = 0.0;
        self.state.routine.new_frame();
        self.stats.measured_work_ratio = 0.0;
        self.stats.refit_ms = 0.0;
        self.stats.rebuild_ms = 0.0;
        // The last frame went unsampled by this mesh's plan (not for want of rays): the policy
        // has nothing new to weigh ([`crate::engine::watch`]).
        let gap = cx.watched && !cx.sampled && !self.state.watch.due();
        let swapped = self.swap_in_background_tree(id, cx);
        out.swapped = swapped;
        self.state.frames_left = cx.frames_left;
        // The deciding policies only refit a tree that cannot degrade; the fixed ones do as
        // they say.
        let early = match cx.forced.or_else(|| self.state.before_refit(cx.policy)) {
            None if self.one_leaf() => Some(Decision::Refit),
            d => d,
        };
        // The wide tree is collapsed again after going back to a binary tree without its own.
        let mut recollapse = false;
        let (decision, raw_work_ratio) = match early {
            Some(Decision::Rebuild) => (Decision::Rebuild, 0.0),
            _ => {
                let t = Instant::now();
                (out.reverted, recollapse) = self.refit(id, cx);
                let (decision, raw) = self.observe_and_decide(id, cx, early, gap, ms_since(t));
                self.stats.refit_ms = ms_since(t);
                (decision, raw)
            }
        };
        let refitted = early != Some(Decision::Rebuild);
        let mut action = Action::from(decision);
        match decision {
            Decision::Refit => self.follow_wide(recollapse, cx),
            Decision::Rebuild => out.reverted |= self.rebuild(id, refitted, raw_work_ratio, cx),
            Decision::Optimize(_) | Decision::Partial(_) => self.restructure(id, decision, cx),
            Decision::Background => {
                self.follow_wide(recollapse, cx);
                let wide = self.wide.is_some();
                // The lag the policy weighed, computed before it decided.
                let due = cx.frame + self.state.background.lag as u64;
                if cx
                    .background
                    .start(id, &self.positions, &self.indices, &cx.build, wide, due)
                {
                    self.stats.model_ms += cx.prices.rebuild_ms(self.indices.len());
                    // The rebuild's cost is paid: the extra trace time counts afresh.
                    self.state.restructured();
                } else {
                    action = Action::Refit;
                }
            }
        }
        if swapped && action == Action::Refit {
            action = Action::AsyncSwap;
        }
        if out.reverted && action == Action::Refit {
            action = Action::Back;
        }
        self.watch(cx, gap);
        self.stats.action = action;
        self.stats.sah = self.sah;
        out
    }

    /// Frames a background build of this mesh started now takes to arrive: as many as the
    /// build (on one thread) takes of tracing, at the prices or the measured times.
    fn background_lag(&self, cx: &FrameContext<'_>) -> f64 {
        let tris = self.indices.len();
        let build_ms = cx.timing.build_ms(self.state.rebuild_ms, tris, &cx.prices)
            * rayon::current_num_threads() as f64;
        if cx.frame_trace_ms > 0.0 {
            (build_ms / cx.frame_trace_ms)
                .ceil()
                .clamp(1.0, MAX_BACKGROUND_LAG)
        } else {
            1.0
        }
    }

    /// Plans the frames the mesh's rays go unsampled after a fresh sample, or counts one of
    /// them down in a `gap` ([`crate::engine::watch`]); a new tree's reference and routine
    /// rebuilds want this frame's sample.
    fn watch(&mut self, cx: &FrameContext<'_>, gap: bool) {
        if !cx.watched {
            return;
        }
        let needed = self.degradation.ratio().is_none() || self.state.routine.now;
        if cx.sampled {
            self.state
                .plan_sample(cx.policy, needed, cx.frame_trace_ms, self.stats.sah_ratio);
        } else if gap {
            self.state.watch.tick(needed, self.stats.sah_ratio);
        }
    }

    /// Swaps in the tree the background worker finished for this mesh, if it has: its policy
    /// state starts from the new tree (built at an earlier pose; the refit that follows brings
    /// it to this frame's). True when it did.
    fn swap_in_background_tree(&mut self, id: MeshId, cx: &mut FrameContext<'_>) -> bool {
        let Some(mut job) = cx.background.take_due(id, cx.frame) else {
            return false;
        };
        let tris = self.indices.len();
        std::mem::swap(&mut self.bvh, &mut job.tree);
        if let (Some(w), Some(jw)) = (&mut self.wide, &mut job.wide) {
            std::mem::swap(w, jw);
        }
        self.sah = super::tree_sah(self.bvh.bvh());
        self.build_poses = 0;
        let cost = match cx.timing {
            Timing::Measured => job.build_ms,
            t => t.build_ms(job.build_ms, tris, &cx.prices),
        };
        self.state.rebuilt(self.sah, 0.0, cost);
        self.degradation.reset();
        cx.background.recycle(job);
        true
    }

    /// Refits the tree (and a replaced tree on probation). Returns whether the probation went
    /// back to the replaced tree, and whether the wide tree must then be collapsed again (the
    /// SAH measure's probation keeps no wide spare).
    fn refit(&mut self, id: MeshId, cx: &FrameContext<'_>) -> (bool, bool) {
        let tris = self.indices.len();
        self.bvh.refit_indexed(&self.positions, &self.indices);
        self.sah = super::tree_sah(self.bvh.bvh());
        self.state.since_build += 1;
        self.stats.model_ms += cx.prices.refit_ms(tris);
        match self.probe.take() {
            Some(p) if cx.trials => {
                let back = ray_probe_step(self, id, p, cx.entries, cx.timing, &cx.prices);
                (back, false)
            }
            Some(p) => {
                let back = probe_step(self, p, cx.timing, &cx.prices);
                (back, back)
            }
            None => (false, false),
        }
    }

    /// Measures the refitted tree's degradation (SAH ratio, fresh-build estimate, ray-work
    /// ratio) and asks the policy (unless it decided before the refit; in a sampling `gap`, with
    /// nothing new to weigh). Returns the decision and the ray-work ratio before calibration
    /// (what a rebuild's replay checks).
    fn observe_and_decide(
        &mut self,
        id: MeshId,
        cx: &FrameContext<'_>,
        early: Option<Decision>,
        gap: bool,
        refit_ms: f64,
    ) -> (Decision, f32) {
        let tris = self.indices.len();
        let (timing, prices) = (cx.timing, &cx.prices);
        let ratio = ratio(self.sah, self.state.build_sah);
        self.stats.sah_ratio = ratio;
        // The fresh ratio: against `build_sah * est(now) / est(last build)`, with the latest
        // estimate when this frame has not earned a new one.
        self.stats.fresh_ratio = if cx.estimate && self.state.build_estimate > 0.0 {
            self.estimate_budget += ESTIMATE_SHARE
                * (self.state.trace_share_ms + timing.refit_ms(refit_ms, tris, prices));
            if self.estimate_budget >= self.estimate_ms {
                let te = Instant::now();
                self.last_estimate = self.fresh.estimate(&self.positions, &self.indices);
                let n = self.fresh.sample_len();
                self.estimate_ms = timing.estimate_ms(ms_since(te), n, prices);
                self.estimate_budget = (self.estimate_budget - self.estimate_ms).max(0.0);
                self.stats.model_ms += prices.estimate_ms(n);
            }
            if self.last_estimate > 0.0 {
                ratio * self.state.build_estimate / self.last_estimate
            } else {
                ratio
            }
        } else if cx.estimate {
            ratio
        } else {
            0.0
        };
        // The ray-work measure: the sampled work per entry into the mesh over the fresh tree's
        // (the first frame after the last build), as far as the last rebuilds' replays showed
        // it right; the policy weighs it as it weighs the SAH's fresh ratio.
        let mut raw = 0.0;
        let (fresh, judged) = if cx.ray_judged {
            // Without a sample (the caller traces without `trace_frame` or `sample_rays`),
            // the SAH's ratio to the last build stands in; it caps a sample of few entries.
            raw = self.degradation.judged(ratio);
            self.stats.work_ratio = 1.0 + self.state.estimate_gain * (raw - 1.0).max(0.0);
            (raw, self.stats.work_ratio)
        } else {
            self.stats.work_ratio = 0.0;
            (self.stats.fresh_ratio, ratio)
        };
        if let Some(d) = early {
            return (d, raw);
        }
        self.set_rung_priors(cx);
        if cx.policy == Policy::Async {
            let lag = self.background_lag(cx);
            let running = cx.background.running(id);
            self.state.expect_background(lag, running, ratio);
        }
        let d = if cx.ray_judged {
            if gap {
                self.state.after_refit_unsampled()
            } else {
                self.state.after_refit_sampled(cx.policy, judged, fresh)
            }
        } else {
            self.state.after_refit(cx.policy, judged, fresh)
        };
        (d, raw)
    }

    /// Before a rung has run on this mesh, its predicted cost is the priced model's.
    fn set_rung_priors(&mut self, cx: &FrameContext<'_>) {
        let n = self.indices.len();
        let (opt, part) = match cx.policy {
            Policy::Optimize(b) => (b, LADDER_PARTIAL),
            Policy::Partial(b) => (LADDER_OPTIMIZE, b),
            _ => (LADDER_OPTIMIZE, LADDER_PARTIAL),
        };
        let [o, p] = &mut self.state.rungs;
        if o.cost_ms.is_infinite() {
            // About `share * n / 4` searches (leaves of about four triangles) of a few dozen
            // visits each.
            let visits = (f64::from(opt) * n as f64 / 4.0 * 32.0) as u64;
            o.cost_ms = cx.prices.optimize_ms(n, visits);
        }
        if p.cost_ms.is_infinite() {
            let cut = crate::bvh::partial::CUT_TARGET.min(n.max(1));
            p.cost_ms = cx
                .prices
                .partial_ms(n, cut, (f64::from(part) * n as f64) as usize);
        }
    }

    /// The wide tree follows the refitted (or reverted-to) binary tree; its time is part of
    /// the refit's.
    fn follow_wide(&mut self, reverted: bool, cx: &FrameContext<'_>) {
        if let Some(w) = &mut self.wide {
            let t = Instant::now();
            if reverted {
                w.collapse_from(&self.bvh);
            } else {
                w.refit_indexed(&self.positions, &self.indices);
            }
            let ms = ms_since(t);
            self.stats.refit_ms += ms;
            self.estimate_budget +=
                ESTIMATE_SHARE * cx.timing.refit_ms(ms, self.indices.len(), &cx.prices);
        }
    }

    /// The replaced tree's work on the previous frame's sampled rays, its wide tree refitted
    /// first (as the rays would have walked it); `None` without a sample.
    fn replay_before(&mut self, id: MeshId, cx: &FrameContext<'_>) -> Option<TraversalStats> {
        if cx.entries.is_empty() {
            return None;
        }
        if let Some(w) = &mut self.wide {
            w.refit_indexed(&self.positions, &self.indices);
        }
        Some(sample::replay_work(
            &self.bvh,
            self.wide.as_ref(),
            id,
            cx.entries,
        ))
    }

    /// The replayed work of the tree an action made against the one it replaced: the old tree's
    /// cost over the new one's (0 without a sample). Returns what both replays cost (ms at the
    /// prices): part of the action's price, since the policy pays it whenever it acts.
    fn replay_after(
        &mut self,
        id: MeshId,
        old: Option<TraversalStats>,
        cx: &FrameContext<'_>,
    ) -> f64 {
        let Some(old) = old else { return 0.0 };
        let new = sample::replay_work(&self.bvh, self.wide.as_ref(), id, cx.entries);
        let (old, new) = (cx.prices.trace_ms(old), cx.prices.trace_ms(new));
        self.stats.model_ms += old + new;
        if new > 0.0 {
            self.stats.measured_work_ratio = (old / new) as f32;
        }
        old + new
    }

    /// A full rebuild, after a refit (`refitted`) or instead of one. Returns true when it was a
    /// trial the replay rejected (the refitted tree stays).
    fn rebuild(
        &mut self,
        id: MeshId,
        refitted: bool,
        raw_work_ratio: f32,
        cx: &mut FrameContext<'_>,
    ) -> bool {
        let tris = self.indices.len();
        let refit_sah = refitted.then_some(self.sah);
        let probe = cx.probes && refitted;
        let t = Instant::now();
        // Routine rebuilds are replayed only when checked.
        let routine = self.state.routine;
        let judged = !routine.now || routine.checked;
        let old_work = if refitted && judged {
            self.replay_before(id, cx)
        } else {
            None
        };
        // A wide tree needs its spare too, or a dropped trial could not bring it back.
        let trial = cx.trials
            && judged
            && old_work.is_some()
            && self.wide.is_some() == self.prev_wide.is_some();
        if probe || trial {
            // Keep the refitted tree: rebuild into the spare.
            std::mem::swap(&mut self.bvh, &mut self.prev);
        }
        if let (true, Some(w), Some(spare)) = (trial, &mut self.wide, &mut self.prev_wide) {
            std::mem::swap(w, spare);
        }
        let poses = self.build_tree(cx.frame, &cx.build, cx.workspace);
        if let Some(w) = &mut self.wide {
            w.collapse_from(&self.bvh);
        }
        self.sah = super::tree_sah(self.bvh.bvh());
        let est = if cx.estimate {
            self.fresh.estimate(&self.positions, &self.indices)
        } else {
            0.0
        };
        self.last_estimate = est;
        self.estimate_budget = 0.0;
        self.stats.model_ms += cx.prices.clip_rebuild_ms(tris, poses);
        if cx.estimate {
            self.stats.model_ms += cx.prices.estimate_ms(self.fresh.sample_len());
        }
        let replay_ms = self.replay_after(id, old_work, cx);
        if trial && routine.now {
            // A fresh tree no better than the refitted one (often the very same tree) is no
            // reason to go on rebuilding.
            self.state
                .routine
                .record_check(self.stats.measured_work_ratio > 1.0);
        }
        let worse = self.stats.measured_work_ratio > 0.0 && self.stats.measured_work_ratio < 1.0;
        if let (true, true, Some(refit_sah)) = (trial, worse, refit_sah) {
            self.reject_rebuild(refit_sah, raw_work_ratio, ms_since(t), replay_ms, cx);
            return true;
        }
        if Self::wants_cut(cx.policy) {
            self.cut.reset(&self.bvh, &mut cx.restructure.partial);
        }
        let rebuild_ms = ms_since(t);
        if let Some(refit_sah) = refit_sah {
            if cx.ray_judged && self.stats.measured_work_ratio > 0.0 {
                self.state
                    .calibrate_rays(raw_work_ratio, self.stats.measured_work_ratio);
            } else if cx.estimate {
                self.state
                    .calibrate(self.stats.fresh_ratio, ratio(refit_sah, self.sah));
            }
        }
        let replaced = self.state;
        // What the policy weighs, the replays that judge it included (the measured time has
        // them already); the statistics keep the measured time.
        let rebuild_cost = match cx.timing {
            Timing::Measured => rebuild_ms,
            t => t.clip_build_ms(rebuild_ms, tris, poses, &cx.prices) + replay_ms,
        };
        let level = self.state.frame_extra_ms;
        self.state.rebuilt(self.sah, est, rebuild_cost);
        self.state.replay_ms = replay_ms;
        if cx.ray_judged && refitted {
            self.state.judge_rebuild(level, rebuild_cost);
        }
        self.probe = None;
        // A probed rebuild (SAH measure) or a kept trial (ray-work measure,
        // [`super::ray_probe_step`]) goes on probation, the replaced tree in the spare; this
        // frame's trace already gains from the new tree, by the SAH's ratio or the replay's.
        let gain = match (probe, refit_sah) {
            (true, Some(refit_sah)) => Some(ratio(refit_sah, self.sah)),
            _ if trial => Some(self.stats.measured_work_ratio),
            _ => None,
        };
        if let Some(gain) = gain {
            let saved = self.state.trace_share_ms * f64::from(gain - 1.0);
            if saved < rebuild_cost {
                self.probe = Some(Probe {
                    state: replaced,
                    saved_ms: saved,
                    cost_ms: 0.0,
                    rebuild_ms: rebuild_cost,
                    frames: 0,
                    next: 1,
                    last: 0,
                    degradation: self.degradation,
                });
            } else if probe {
                self.state.rebuild_paid();
            }
        }
        self.stats.sah_ratio = 1.0;
        self.stats.fresh_ratio = if cx.estimate { 1.0 } else { 0.0 };
        self.stats.work_ratio = if cx.ray_judged { 1.0 } else { 0.0 };
        self.degradation.reset();
        self.stats.rebuild_ms = rebuild_ms;
        false
    }

    /// Undoes a trial rebuild whose tree did worse on the replayed rays than the refitted one
    /// it was to replace: the refitted trees come back, and the policy learns from the replay
    /// and from what the rebuild cost ([`crate::engine::policy::PolicyState::rebuild_rejected`]).
    fn reject_rebuild(
        &mut self,
        refit_sah: f32,
        raw_work_ratio: f32,
        ms: f64,
        replay_ms: f64,
        cx: &FrameContext<'_>,
    ) {
        std::mem::swap(&mut self.bvh, &mut self.prev);
        if let (Some(w), Some(spare)) = (&mut self.wide, &mut self.prev_wide) {
            std::mem::swap(w, spare);
        }
        self.sah = refit_sah;
        self.state
            .calibrate_rays(raw_work_ratio, self.stats.measured_work_ratio);
        let cost = match cx.timing {
            Timing::Measured => ms,
            t => t.clip_build_ms(ms, self.indices.len(), self.build_poses, &cx.prices) + replay_ms,
        };
        self.state.rebuild_rejected(cost);
        self.state.replay_ms = replay_ms;
        self.stats.rebuild_ms = ms;
    }

    /// An intermediate rung after the refit: optimise or partly rebuild the tree, collapse the
    /// wide tree again, and teach the policy what it cost and won back (by the replayed rays
    /// under the ray-work measure, else by the SAH).
    fn restructure(&mut self, id: MeshId, decision: Decision, cx: &mut FrameContext<'_>) {
        let tris = self.indices.len();
        // A probation ends: the kept tree no longer matches this one.
        self.probe = None;
        let t = Instant::now();
        let old_work = self.replay_before(id, cx);
        let sah_before = self.sah;
        let r = &mut *cx.restructure;
        let modelled = match decision {
            Decision::Optimize(share) => {
                let budget = OptimizeBudget {
                    share,
                    ..OptimizeBudget::default()
                };
                let st = self.bvh.optimize(budget, &mut r.ws, &mut r.optimize);
                // The cut's subtrees moved: the next partial rebuild takes a new one.
                self.cut.clear();
                cx.prices.optimize_ms(tris, st.visits)
            }
            Decision::Partial(share) => {
                let st = self.bvh.partial_rebuild(
                    &mut self.cut,
                    share,
                    &cx.build,
                    &mut r.ws,
                    &mut r.partial,
                );
                cx.prices
                    .partial_ms(tris, st.cut as usize, st.rebuilt_tris as usize)
            }
            Decision::Refit | Decision::Rebuild | Decision::Background => 0.0,
        };
        if let Some(w) = &mut self.wide {
            w.collapse_from(&self.bvh);
        }
        self.sah = super::tree_sah(self.bvh.bvh());
        self.stats.model_ms += modelled;
        let replay_ms = self.replay_after(id, old_work, cx);
        let ms = ms_since(t);
        let cost = match cx.timing {
            Timing::Measured => ms,
            _ => modelled + replay_ms,
        };
        // What the degradation was and what is left of it.
        let (before, after) = if cx.ray_judged && self.stats.measured_work_ratio > 0.0 {
            let before = self.stats.work_ratio.max(1.0);
            (before, before / self.stats.measured_work_ratio)
        } else {
            let before = self.stats.sah_ratio;
            (
                before,
                before * self.sah / sah_before.max(f32::MIN_POSITIVE),
            )
        };
        if let Some(k) = decision.rung() {
            self.state.rungs[k].learn(cost, before, after);
        }
        self.state.restructured();
        self.stats.sah_ratio = ratio(self.sah, self.state.build_sah);
        self.stats.rebuild_ms = ms;
    }
}

/// The most frames a background rebuild is given before the engine waits for it.
const MAX_BACKGROUND_LAG: f64 = 64.0;
