//! The oracle's inputs: every tree a deforming mesh can have at every frame, measured. For each
//! build frame `b` the scene is built at `b` and refitted through every later frame `f`; at
//! each `f` the mesh's tree is recorded by its SAH cost and by the ray work of frame `f`'s
//! sampled rays (the bench's sample, whose entries every run shares, replayed on this tree).
//! `O(F^2)` refits and replays.

use crate::engine::oracle::{RungCosts, WorkCosts};
use crate::engine::ray_work::SampleEntry;
use crate::engine::source::FrameSource;
use crate::engine::{Decision, Engine, EngineConfig, MeshId, Policy, Prices};

/// One frame's sampled rays, as every run of the bench saw them.
#[derive(Clone, Debug, Default)]
pub struct SampledFrame {
    /// Entries of the sampled rays into instances (tree-independent: see
    /// [`crate::engine::ray_work`]).
    pub entries: Vec<SampleEntry>,
    /// Modelled trace cost no schedule changes: the top-level tree and the meshes that do not
    /// deform, ms.
    pub fixed_ms: f64,
    /// From the sample's work to the frame's: rays per sampled ray.
    pub scale: f64,
}

impl SampledFrame {
    /// Modelled cost of the frame's rays in `mesh`'s tree in `e` (the sample replayed on it,
    /// scaled to the frame), ms.
    #[must_use]
    pub fn replay_ms(&self, e: &Engine, mesh: MeshId, prices: &Prices) -> f64 {
        self.scale * prices.trace_ms(e.mesh_work_on(mesh, &self.entries))
    }
}

/// What the all-pairs pass measured.
#[derive(Clone, Debug, Default)]
pub struct AllPairs {
    /// `sah[mesh][b][f - b]`: SAH cost at frame `f` of the tree built at `b`.
    pub sah: Vec<Vec<Vec<f32>>>,
    /// Each deforming mesh's costs in the modelled measure.
    pub work: Vec<WorkCosts>,
}

/// Runs the pass over frames `0 ..= frames` (`sampled[f]` for frame `f`; index 0 unused) with
/// engines made by `config` (its policy is irrelevant: every tree is refitted), pricing refits,
/// rebuilds and ray work at `prices`.
pub fn measure(
    src: &mut dyn FrameSource,
    config: EngineConfig,
    sampled: &[SampledFrame],
    prices: &Prices,
    frames: usize,
) -> AllPairs {
    let ids = src.deforming().to_vec();
    let config = EngineConfig {
        policy: Policy::Refit,
        ..config
    };
    let mut sah = vec![vec![Vec::new(); frames + 1]; ids.len()];
    let mut trace = vec![vec![Vec::new(); frames + 1]; ids.len()];
    let mut tris = vec![0; ids.len()];
    // What a rebuild at each frame costs: plain, or clip-aware for the poses still ahead.
    let mut rebuild_ms = vec![Vec::with_capacity(frames + 1); ids.len()];
    for b in 0..=frames {
        let mut e = src.build(b, config);
        if b == 0 {
            for (t, m) in tris.iter_mut().zip(&ids) {
                *t = e.indices(*m).len();
            }
        }
        for ((r, m), &t) in rebuild_ms.iter_mut().zip(&ids).zip(&tris) {
            r.push(prices.clip_rebuild_ms(t, e.mesh_build_poses(*m)));
        }
        for (f, frame) in sampled.iter().enumerate().take(frames + 1).skip(b) {
            if f > b {
                src.advance(&mut e, f);
                e.update();
            }
            for (k, m) in ids.iter().enumerate() {
                sah[k][b].push(e.mesh_stats(*m).sah);
                let w = if f == 0 {
                    0.0
                } else {
                    frame.replay_ms(&e, *m, prices)
                };
                trace[k][b].push(w);
            }
        }
    }
    let work = tris
        .iter()
        .zip(trace)
        .zip(rebuild_ms)
        .map(|((&tris, trace_ms), rebuild_ms)| WorkCosts {
            refit_ms: vec![prices.refit_ms(tris); frames + 1],
            rebuild_ms,
            trace_ms,
        })
        .collect();
    AllPairs { sah, work }
}

/// The rungs' inputs to the oracle ([`WorkCosts::best_with_rungs`]): for each rung, build
/// frame `b` and frame `o > b`, the scene is built at `b`, refitted to `o` and restructured
/// there by the rung, then refitted through every later frame; each deforming mesh's update at
/// `o` and trace cost at every frame from `o` on are recorded. `O(F^2)` builds and `O(F^3)`
/// refits and replays per rung. Returns `[mesh][rung]`.
pub fn measure_rungs(
    src: &mut dyn FrameSource,
    config: EngineConfig,
    sampled: &[SampledFrame],
    prices: &Prices,
    frames: usize,
    rungs: &[Decision],
) -> Vec<Vec<RungCosts>> {
    let ids = src.deforming().to_vec();
    // The ladder's engine: its trees are cut for partial rebuilds at every build, as the
    // rung policies' are.
    let config = EngineConfig {
        policy: Policy::Ladder,
        ..config
    };
    let mut out = vec![Vec::new(); ids.len()];
    for &rung in rungs {
        let mut costs = vec![
            RungCosts {
                update_ms: vec![Vec::new(); frames + 1],
                trace_ms: vec![Vec::new(); frames + 1],
            };
            ids.len()
        ];
        for b in 0..frames {
            for o in b + 1..=frames {
                let mut e = src.build(b, config);
                src.advance(&mut e, o);
                e.force_next(rung);
                e.update();
                let mut row = Vec::with_capacity(ids.len());
                for (k, m) in ids.iter().enumerate() {
                    costs[k].update_ms[b].push(e.mesh_stats(*m).model_ms);
                    let mut r = Vec::with_capacity(frames + 1 - o);
                    r.push(sampled[o].replay_ms(&e, *m, prices));
                    row.push(r);
                }
                for (f, frame) in sampled.iter().enumerate().take(frames + 1).skip(o + 1) {
                    src.advance(&mut e, f);
                    e.force_next(Decision::Refit);
                    e.update();
                    for (k, m) in ids.iter().enumerate() {
                        row[k].push(frame.replay_ms(&e, *m, prices));
                    }
                }
                for (k, r) in row.into_iter().enumerate() {
                    costs[k].trace_ms[b].push(r);
                }
            }
        }
        for (k, c) in costs.into_iter().enumerate() {
            out[k].push(c);
        }
    }
    out
}
