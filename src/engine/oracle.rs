//! The best refit-or-rebuild schedule in hindsight, for judging policies.
//!
//! For one deforming mesh over frames `1 ..= F` (its tree built at frame 0) the oracle chooses
//! at every frame to refit or rebuild so that the total of update and trace cost is least; the
//! state is the frame `b` the tree was last built at, so dynamic programming over `(f, b)`
//! finds the exact optimum in `O(F^2)`. Meshes are independent (a ray's entry into each
//! instance does not depend on the trees, see [`super::ray_work`]), so the scene's oracle is
//! the sum of the meshes' plus what no schedule changes.
//!
//! Two cost models fill it: [`WorkCosts`], the **modelled** measure (updates priced by their
//! work and every tree `b -> f` traced on frame `f`'s sampled rays at the engine's
//! [`super::Prices`]), which no policy can beat; and [`MeshCosts`], the **wall-clock**
//! measure (measured update times, trace time modelled from the SAH and calibrated by
//! [`SceneCosts::calibrate`]), kept beside it for comparison: it follows the machine's load,
//! so policies can come out slightly below it (`docs/internals.md`, the benchmark).
//! [`WorkCosts::best_with_rungs`] (`oracle/rungs.rs`) adds the rungs between refit and
//! rebuild to the moves, [`WorkCosts::best_going_back`] (`oracle/back.rs`) going back to the
//! tree the last rebuild replaced.

mod back;
mod rungs;
pub use back::{BACK_MAX_FRAMES, BackMove, BackSchedule};
pub use rungs::{Move, RungCosts, RungSchedule};

/// The measured and recorded costs of one mesh over frames `0 ..= F` (index 0, the initial
/// build, costs nothing).
#[derive(Clone, Debug, Default)]
pub struct MeshCosts {
    /// Refit time at each frame, ms.
    pub refit_ms: Vec<f64>,
    /// Rebuild time at each frame, ms.
    pub rebuild_ms: Vec<f64>,
    /// This mesh's share of the frame's trace time with a fresh tree, ms.
    pub fresh_trace_ms: Vec<f64>,
    /// `sah[b][f - b]`: SAH cost at frame `f` of the tree built at frame `b`; `sah[f][0]` is
    /// the fresh tree's.
    pub sah: Vec<Vec<f32>>,
}

impl MeshCosts {
    /// Number of frames after the initial one.
    #[must_use]
    pub fn frames(&self) -> usize {
        self.refit_ms.len().saturating_sub(1)
    }

    /// Modelled extra trace time at frame `f` of the tree built at `b` over a fresh tree,
    /// uncalibrated (`α = 1`: `fresh × (ratio − 1)`, a ratio below 1 counting as 1).
    #[must_use]
    pub fn extra_trace_ms(&self, b: usize, f: usize) -> f64 {
        let fresh = f64::from(self.sah[f][0]);
        let aged = f64::from(self.sah[b][f - b]);
        if fresh > 0.0 {
            self.fresh_trace_ms[f] * (aged / fresh - 1.0).max(0.0)
        } else {
            0.0
        }
    }

    /// SAH ratio at frame `f` of the tree built at `b` to a fresh tree's.
    #[must_use]
    pub fn true_ratio(&self, b: usize, f: usize) -> f32 {
        let fresh = self.sah[f][0];
        if fresh > 0.0 {
            self.sah[b][f - b] / fresh
        } else {
            1.0
        }
    }

    /// Modelled cost (update plus extra trace time) of a given schedule: `rebuild[f]` for
    /// frames `1 ..= F` (index 0 ignored); uncalibrated (`α = 1`).
    #[must_use]
    pub fn cost_of(&self, rebuild: &[bool]) -> f64 {
        self.cost_of_with(rebuild, 1.0)
    }

    /// [`MeshCosts::cost_of`] with the extra trace time scaled by `alpha`.
    #[must_use]
    pub fn cost_of_with(&self, rebuild: &[bool], alpha: f64) -> f64 {
        let mut b = 0;
        let mut total = 0.0;
        for (f, &r) in rebuild.iter().enumerate().take(self.frames() + 1).skip(1) {
            if r {
                b = f;
                total += self.rebuild_ms[f];
            } else {
                total += self.refit_ms[f] + alpha * self.extra_trace_ms(b, f);
            }
        }
        total
    }

    /// Update and uncalibrated extra trace time of always refitting: `(refits, extra)`.
    fn always_refit_parts(&self) -> (f64, f64) {
        (1..=self.frames()).fold((0.0, 0.0), |(u, x), f| {
            (u + self.refit_ms[f], x + self.extra_trace_ms(0, f))
        })
    }
}

/// The best schedule for one mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Schedule {
    /// Modelled update time plus extra trace time over fresh trees, ms.
    pub cost_ms: f64,
    /// `rebuild[f]` for frames `0 ..= F` (frame 0 is the initial build, always true).
    pub rebuild: Vec<bool>,
}

impl Schedule {
    /// Number of rebuilds after the initial build.
    #[must_use]
    pub fn rebuilds(&self) -> usize {
        self.rebuild.iter().skip(1).filter(|&&r| r).count()
    }
}

/// The schedule of least modelled cost, by dynamic programming over the frame of the last
/// build; uncalibrated (`α = 1`).
#[must_use]
pub fn best_schedule(c: &MeshCosts) -> Schedule {
    best_schedule_with(c, 1.0)
}

/// [`best_schedule`] with the extra trace time scaled by `alpha` (the calibrated model).
#[must_use]
pub fn best_schedule_with(c: &MeshCosts, alpha: f64) -> Schedule {
    best_by(
        c.frames(),
        |b, f| c.refit_ms[f] + alpha * c.extra_trace_ms(b, f),
        |f| c.rebuild_ms[f],
    )
}

/// One mesh's costs in the modelled measure over frames `0 ..= F`: refit and rebuild priced
/// by their work, and the trace cost of every tree the mesh can have at every frame, priced by
/// the ray work the frame's sampled rays cost in it.
#[derive(Clone, Debug, Default)]
pub struct WorkCosts {
    /// Modelled refit at each frame, ms.
    pub refit_ms: Vec<f64>,
    /// Modelled rebuild at each frame, ms.
    pub rebuild_ms: Vec<f64>,
    /// `trace_ms[b][f - b]`: modelled trace cost at frame `f` of the tree built at frame `b`
    /// and refitted to `f` (`trace_ms[f][0]`: the fresh tree's), ms.
    pub trace_ms: Vec<Vec<f64>>,
}

impl WorkCosts {
    /// Number of frames after the initial one.
    #[must_use]
    pub fn frames(&self) -> usize {
        self.refit_ms.len().saturating_sub(1)
    }

    /// Modelled cost of frames `1 ..= F` under a schedule (`rebuild[f]`, index 0 ignored):
    /// each frame's update plus its trace cost with the tree the schedule has then.
    #[must_use]
    pub fn cost_of(&self, rebuild: &[bool]) -> f64 {
        let mut b = 0;
        let mut total = 0.0;
        for (f, &r) in rebuild.iter().enumerate().take(self.frames() + 1).skip(1) {
            if r {
                b = f;
                total += self.rebuild_ms[f] + self.trace_ms[f][0];
            } else {
                total += self.refit_ms[f] + self.trace_ms[b][f - b];
            }
        }
        total
    }

    /// The trace cost at frame `f` of the tree built at `b` over the fresh tree's: the
    /// degradation the rays felt.
    #[must_use]
    pub fn ratio(&self, b: usize, f: usize) -> f64 {
        let fresh = self.trace_ms[f][0];
        if fresh > 0.0 {
            self.trace_ms[b][f - b] / fresh
        } else {
            1.0
        }
    }

    /// The schedule of least modelled cost: the exact optimum over refit-or-rebuild schedules.
    #[must_use]
    pub fn best(&self) -> Schedule {
        best_by(
            self.frames(),
            |b, f| self.refit_ms[f] + self.trace_ms[b][f - b],
            |f| self.rebuild_ms[f] + self.trace_ms[f][0],
        )
    }
}

/// The least-cost schedule over frames `1 ..= n` by dynamic programming over the frame of the
/// last build: `keep(b, f)` is frame `f`'s cost when the tree built at `b` is refitted,
/// `rebuild(f)` its cost when the tree is rebuilt at `f`. `O(n^2)`.
fn best_by(
    n: usize,
    keep: impl Fn(usize, usize) -> f64,
    rebuild: impl Fn(usize) -> f64,
) -> Schedule {
    // cost[b] after frame f: least cost of frames 1..=f with the tree last built at b;
    // parent[f]: the build frame before f when the tree was rebuilt at f.
    let mut cost = vec![f64::INFINITY; n + 1];
    cost[0] = 0.0;
    let mut parent = vec![0usize; n + 1];
    for f in 1..=n {
        // Rebuild at f: from the best state of frame f - 1.
        let (best_b, best) = cost[..f]
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map(|(b, &c)| (b, c))
            .unwrap_or((0, 0.0));
        for (b, cb) in cost.iter_mut().enumerate().take(f) {
            if cb.is_finite() {
                *cb += keep(b, f);
            }
        }
        cost[f] = best + rebuild(f);
        parent[f] = best_b;
    }
    let (mut b, total) = cost
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map(|(b, &c)| (b, c))
        .unwrap_or((0, 0.0));
    let mut rebuild = vec![false; n + 1];
    while b > 0 {
        rebuild[b] = true;
        b = parent[b];
    }
    rebuild[0] = true;
    Schedule {
        cost_ms: total,
        rebuild,
    }
}

/// A scene's costs: what no schedule changes, and each deforming mesh's [`MeshCosts`].
#[derive(Clone, Debug, Default)]
pub struct SceneCosts {
    /// Pose, top-level tree and tracing with fresh trees over all frames, ms.
    pub fixed_ms: f64,
    /// Every deforming mesh.
    pub meshes: Vec<MeshCosts>,
}

/// The calibrated model of a scene and its endpoints (see the module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Calibration {
    /// Scale of the modelled extra trace time (`α ≥ 0`).
    pub alpha: f64,
    /// False when nothing could be fitted (no deforming mesh, or a refitted tree never
    /// modelled slower than fresh ones): `alpha` is then 1.
    pub fitted: bool,
    /// Modelled always-refit total with `alpha`, ms.
    pub model_refit_ms: f64,
    /// Modelled always-rebuild total, ms.
    pub model_rebuild_ms: f64,
    /// Modelled always-refit total with `α = 1`, ms.
    pub uncalibrated_refit_ms: f64,
}

impl SceneCosts {
    /// Modelled total of a schedule per mesh under `alpha`, ms.
    #[must_use]
    pub fn cost_of(&self, rebuild: &[Vec<bool>], alpha: f64) -> f64 {
        self.fixed_ms
            + self
                .meshes
                .iter()
                .zip(rebuild)
                .map(|(m, r)| m.cost_of_with(r, alpha))
                .sum::<f64>()
    }

    /// Modelled totals of always refitting and always rebuilding under `alpha`, ms.
    #[must_use]
    pub fn endpoints(&self, alpha: f64) -> (f64, f64) {
        let (mut refit, mut rebuild) = (self.fixed_ms, self.fixed_ms);
        for m in &self.meshes {
            let n = m.frames() + 1;
            refit += m.cost_of_with(&vec![false; n], alpha);
            rebuild += m.cost_of_with(&vec![true; n], alpha);
        }
        (refit, rebuild)
    }

    /// Fits `α` so that the modelled always-refit total equals `measured_refit_ms` (the
    /// always-refit run's measured total: update plus trace over all frames), `α ≥ 0`.
    #[must_use]
    pub fn calibrate(&self, measured_refit_ms: f64) -> Calibration {
        let (updates, extra) = self
            .meshes
            .iter()
            .map(MeshCosts::always_refit_parts)
            .fold((0.0, 0.0), |(u, x), (mu, mx)| (u + mu, x + mx));
        let base = self.fixed_ms + updates;
        let fitted = extra > 1e-9 * base.abs().max(1e-9);
        let alpha = if fitted {
            ((measured_refit_ms - base) / extra).max(0.0)
        } else {
            1.0
        };
        let (model_refit_ms, model_rebuild_ms) = self.endpoints(alpha);
        Calibration {
            alpha,
            fitted,
            model_refit_ms,
            model_rebuild_ms,
            uncalibrated_refit_ms: base + extra,
        }
    }

    /// The best schedule of every mesh under `alpha`, and the scene's modelled total.
    #[must_use]
    pub fn best(&self, alpha: f64) -> (f64, Vec<Schedule>) {
        let s: Vec<Schedule> = self
            .meshes
            .iter()
            .map(|m| best_schedule_with(m, alpha))
            .collect();
        (self.fixed_ms + s.iter().map(|s| s.cost_ms).sum::<f64>(), s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every schedule of a short sequence, by brute force.
    fn exhaustive(c: &MeshCosts, alpha: f64) -> f64 {
        let n = c.frames();
        (0..1u32 << n)
            .map(|mask| {
                let mut r = vec![true];
                r.extend((0..n).map(|k| mask >> k & 1 == 1));
                c.cost_of_with(&r, alpha)
            })
            .fold(f64::INFINITY, f64::min)
    }

    fn costs(n: usize, seed: u64) -> MeshCosts {
        let mut s = seed;
        let mut rnd = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 33) as f64 / (1u64 << 31) as f64
        };
        let mut c = MeshCosts {
            refit_ms: (0..=n).map(|_| 0.5 + rnd()).collect(),
            rebuild_ms: (0..=n).map(|_| 2.0 + 8.0 * rnd()).collect(),
            fresh_trace_ms: (0..=n).map(|_| 1.0 + 4.0 * rnd()).collect(),
            sah: Vec::new(),
        };
        for b in 0..=n {
            let fresh = 10.0 + rnd() as f32;
            let mut row = vec![fresh];
            for _ in b + 1..=n {
                let last = *row.last().unwrap();
                row.push(last * (1.0 + 0.3 * rnd() as f32));
            }
            c.sah.push(row);
        }
        c
    }

    fn work_costs(n: usize, seed: u64) -> WorkCosts {
        let m = costs(n, seed);
        WorkCosts {
            trace_ms: (0..=n)
                .map(|b| {
                    (b..=n)
                        .map(|f| m.fresh_trace_ms[f] * f64::from(m.sah[b][f - b] / m.sah[f][0]))
                        .collect()
                })
                .collect(),
            refit_ms: m.refit_ms,
            rebuild_ms: m.rebuild_ms,
        }
    }

    #[test]
    fn the_work_oracle_is_the_exhaustive_optimum() {
        for seed in 0..60 {
            let n = 1 + seed as usize % 12;
            let c = work_costs(n, seed);
            let s = c.best();
            let want = (0..1u32 << n)
                .map(|mask| {
                    let mut r = vec![true];
                    r.extend((0..n).map(|k| mask >> k & 1 == 1));
                    c.cost_of(&r)
                })
                .fold(f64::INFINITY, f64::min);
            assert!(
                (s.cost_ms - want).abs() < 1e-9,
                "seed {seed}: {} vs {want}",
                s.cost_ms
            );
            assert!((c.cost_of(&s.rebuild) - s.cost_ms).abs() < 1e-9);
            // Never above either endpoint.
            assert!(s.cost_ms <= c.cost_of(&vec![false; n + 1]) + 1e-9);
            assert!(s.cost_ms <= c.cost_of(&vec![true; n + 1]) + 1e-9);
        }
    }

    #[test]
    fn dynamic_programming_matches_exhaustive_search() {
        for seed in 0..40 {
            let c = costs(1 + seed as usize % 10, seed);
            for alpha in [1.0, 0.4, 0.0, 2.5] {
                let s = best_schedule_with(&c, alpha);
                let want = exhaustive(&c, alpha);
                assert!(
                    (s.cost_ms - want).abs() < 1e-9,
                    "seed {seed}, alpha {alpha}: {} vs {want}",
                    s.cost_ms
                );
                assert!((c.cost_of_with(&s.rebuild, alpha) - s.cost_ms).abs() < 1e-9);
            }
            assert_eq!(best_schedule(&c), best_schedule_with(&c, 1.0));
        }
    }

    /// Synthetic measured runs: the calibrated model reproduces both endpoint totals, and the
    /// oracle is never above either.
    #[test]
    fn calibration_reproduces_both_measured_endpoints() {
        for seed in 0..20 {
            let n = 5 + seed as usize % 20;
            let meshes: Vec<MeshCosts> =
                (0..1 + seed % 3).map(|k| costs(n, seed * 7 + k)).collect();
            let fixed_ms = 100.0 + seed as f64;
            let scene = SceneCosts { fixed_ms, meshes };
            // The measured always-rebuild run: its trace is the fixed part (fresh trees), its
            // updates the rebuilds.
            let measured_rebuild = fixed_ms
                + scene
                    .meshes
                    .iter()
                    .map(|m| m.rebuild_ms[1..].iter().sum::<f64>())
                    .sum::<f64>();
            // The measured always-refit run: refits plus some true fraction of the SAH model's
            // extra trace time.
            let true_alpha = [0.55, 0.0, 1.0, 1.7][seed as usize % 4];
            let measured_refit = fixed_ms
                + scene
                    .meshes
                    .iter()
                    .map(|m| {
                        (1..=n)
                            .map(|f| m.refit_ms[f] + true_alpha * m.extra_trace_ms(0, f))
                            .sum::<f64>()
                    })
                    .sum::<f64>();
            let cal = scene.calibrate(measured_refit);
            assert!(cal.fitted);
            assert!(
                (cal.alpha - true_alpha).abs() < 1e-9,
                "{} vs {true_alpha}",
                cal.alpha
            );
            assert!((cal.model_refit_ms - measured_refit).abs() < 1e-6);
            assert!((cal.model_rebuild_ms - measured_rebuild).abs() < 1e-6);
            if true_alpha <= 1.0 {
                assert!(cal.uncalibrated_refit_ms >= cal.model_refit_ms - 1e-9);
            }
            let (oracle, schedules) = scene.best(cal.alpha);
            assert_eq!(schedules.len(), scene.meshes.len());
            assert!(oracle <= measured_refit + 1e-6 && oracle <= measured_rebuild + 1e-6);
            let r: Vec<Vec<bool>> = schedules.iter().map(|s| s.rebuild.clone()).collect();
            assert!((scene.cost_of(&r, cal.alpha) - oracle).abs() < 1e-6);
        }
        // A refit run measured faster than the model's floor: alpha clamps at 0.
        let scene = SceneCosts {
            fixed_ms: 50.0,
            meshes: vec![costs(8, 3)],
        };
        let cal = scene.calibrate(0.0);
        assert_eq!(cal.alpha, 0.0);
        // Nothing deforms: nothing to fit.
        let cal = SceneCosts {
            fixed_ms: 50.0,
            meshes: Vec::new(),
        }
        .calibrate(52.0);
        assert!(!cal.fitted);
        assert_eq!((cal.model_refit_ms, cal.model_rebuild_ms), (50.0, 50.0));
    }
}
