//! The best refit/rebuild schedule in hindsight, for evaluating policies.
//!
//! For one deforming mesh over frames `1 ..= F` (its tree built at frame 0), the oracle chooses
//! at every frame to refit or rebuild so that the total of update and trace time is least. The
//! state is the frame `b` the tree was last built at; dynamic programming over `(frame, b)`
//! takes `O(F^2)`.
//!
//! What is measured and what is modelled:
//! - refit and rebuild times of frame `f` are **measured** (in the always-refit and
//!   always-rebuild runs over the same frames; a refit's cost does not depend on when the tree
//!   was built, only its quality does);
//! - the trace time of frame `f` with a tree built at `b` is **modelled**: the measured trace
//!   time of frame `f` with freshly built trees (the always-rebuild run), the mesh's share of it
//!   (by area-weighted SAH), times `SAH(b -> f) / SAH(f)`: the recorded SAH cost of the tree
//!   built at `b` and refitted to frame `f`, over the cost of the tree built at `f`. Those SAH
//!   costs are recorded for every pair `b <= f` by building at every frame and refitting
//!   through all later ones.
//!
//! Meshes are independent under this model (the trace model is a sum of per-mesh terms), so the
//! scene's oracle is the sum of per-mesh oracles plus the costs no schedule changes.

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

    /// Modelled extra trace time at frame `f` of the tree built at `b` over a fresh tree.
    #[must_use]
    pub fn extra_trace_ms(&self, b: usize, f: usize) -> f64 {
        let fresh = f64::from(self.sah[f][0]);
        let aged = f64::from(self.sah[b][f - b]);
        if fresh > 0.0 {
            self.fresh_trace_ms[f] * (aged / fresh - 1.0)
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
    /// frames `1 ..= F` (index 0 ignored).
    #[must_use]
    pub fn cost_of(&self, rebuild: &[bool]) -> f64 {
        let mut b = 0;
        let mut total = 0.0;
        for (f, &r) in rebuild.iter().enumerate().take(self.frames() + 1).skip(1) {
            if r {
                b = f;
                total += self.rebuild_ms[f];
            } else {
                total += self.refit_ms[f] + self.extra_trace_ms(b, f);
            }
        }
        total
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
/// build.
#[must_use]
pub fn best_schedule(c: &MeshCosts) -> Schedule {
    let n = c.frames();
    // cost[b] after frame f: least cost of frames 1..=f with the tree last built at b;
    // from[f][b]: the build frame before f when the tree was rebuilt at f.
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
                *cb += c.refit_ms[f] + c.extra_trace_ms(b, f);
            }
        }
        cost[f] = best + c.rebuild_ms[f];
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every schedule of a short sequence, by brute force.
    fn exhaustive(c: &MeshCosts) -> f64 {
        let n = c.frames();
        (0..1u32 << n)
            .map(|mask| {
                let mut r = vec![true];
                r.extend((0..n).map(|k| mask >> k & 1 == 1));
                c.cost_of(&r)
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

    #[test]
    fn dynamic_programming_matches_exhaustive_search() {
        for seed in 0..40 {
            let c = costs(1 + seed as usize % 10, seed);
            let s = best_schedule(&c);
            let want = exhaustive(&c);
            assert!(
                (s.cost_ms - want).abs() < 1e-9,
                "seed {seed}: {} vs {want}",
                s.cost_ms
            );
            assert!((c.cost_of(&s.rebuild) - s.cost_ms).abs() < 1e-9);
        }
    }
}
