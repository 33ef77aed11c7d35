//! The best schedule in hindsight when going back to the tree the last rebuild replaced is a
//! move too (the engine keeps that tree in its spare after a kept trial and may return to it:
//! `engine/scene/mesh_update.rs`).
//!
//! A refitted tree depends only on the frame it was built at and the pose it is refitted to,
//! so the state is the pair `(b, s)`: the tree in use built at `b`, the spare at `s` (or none
//! before the first rebuild). Refit keeps `(b, s)`; a rebuild at `f` makes `(f, b)`; going back
//! makes `(s, b)` and costs one refit (of the spare, to the frame's pose). Dynamic programming
//! over the `O(F^2)` states finds the exact optimum over these moves in `O(F^3)`.

use super::WorkCosts;

/// Most frames the oracle goes back over: its table of moves takes `F^3` bytes (64 MB here).
pub const BACK_MAX_FRAMES: usize = 400;

/// One frame's move for one mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackMove {
    /// Refit the tree in use.
    Refit,
    /// Build a fresh tree; the replaced one becomes the spare.
    Rebuild,
    /// Refit the spare and use it; the tree it replaces becomes the spare.
    Back,
}

/// The best schedule over refits, rebuilds and going back.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BackSchedule {
    /// Modelled update and trace cost of frames `1 ..= F`, ms.
    pub cost_ms: f64,
    /// The move at each frame `0 ..= F` (frame 0: the initial build).
    pub moves: Vec<BackMove>,
}

impl BackSchedule {
    /// Frames with the move `m`.
    #[must_use]
    pub fn frames_with(&self, m: BackMove) -> Vec<usize> {
        (1..self.moves.len())
            .filter(|&f| self.moves[f] == m)
            .collect()
    }
}

impl WorkCosts {
    /// The modelled cost of frames `1 ..= F` under `moves` (index 0 ignored); `None` when it
    /// goes back with no spare.
    #[must_use]
    pub fn cost_going_back(&self, moves: &[BackMove]) -> Option<f64> {
        let (mut b, mut s) = (0, None);
        let mut total = 0.0;
        for (f, &m) in moves.iter().enumerate().take(self.frames() + 1).skip(1) {
            match m {
                BackMove::Refit => total += self.refit_ms[f] + self.trace_ms[b][f - b],
                BackMove::Rebuild => {
                    s = Some(b);
                    b = f;
                    total += self.rebuild_ms[f] + self.trace_ms[f][0];
                }
                BackMove::Back => {
                    let spare = s?;
                    s = Some(b);
                    b = spare;
                    total += self.refit_ms[f] + self.trace_ms[b][f - b];
                }
            }
        }
        Some(total)
    }

    /// The least-cost schedule when the moves include going back to the spare tree; over
    /// more than [`BACK_MAX_FRAMES`] frames, [`WorkCosts::best`]'s (refits and rebuilds only).
    #[must_use]
    pub fn best_going_back(&self) -> BackSchedule {
        let n = self.frames();
        if n > BACK_MAX_FRAMES {
            let s = self.best();
            let moves = s
                .rebuild
                .iter()
                .map(|&r| {
                    if r {
                        BackMove::Rebuild
                    } else {
                        BackMove::Refit
                    }
                })
                .collect();
            return BackSchedule {
                cost_ms: s.cost_ms,
                moves,
            };
        }
        // State (b, s): index b * w + s1, s1 = 0 for no spare, else the spare's frame + 1.
        let w = n + 2;
        let states = (n + 1) * w;
        let mut cost = vec![f64::INFINITY; states];
        let mut next = vec![f64::INFINITY; states];
        cost[0] = 0.0;
        // The move that reached each state at each frame; a rebuild's predecessor is the
        // cheapest state with the replaced tree in use, kept per tree.
        let mut how = vec![BackMove::Refit; (n + 1) * states];
        let mut rebuilt_from = vec![0usize; (n + 1) * (n + 1)];
        for f in 1..=n {
            next.fill(f64::INFINITY);
            let at = |m: &mut [BackMove], i: usize, mv: BackMove| m[f * states + i] = mv;
            for b in 0..f {
                // Rebuild: from the cheapest state with `b` in use.
                let (s1, c) = (0..w)
                    .map(|s1| (s1, cost[b * w + s1]))
                    .min_by(|x, y| x.1.total_cmp(&y.1))
                    .unwrap_or((0, f64::INFINITY));
                if c.is_finite() {
                    let i = f * w + b + 1;
                    let v = c + self.rebuild_ms[f] + self.trace_ms[f][0];
                    if v < next[i] {
                        next[i] = v;
                        at(&mut how, i, BackMove::Rebuild);
                        rebuilt_from[f * (n + 1) + b] = s1;
                    }
                }
                for s1 in 0..w {
                    let c = cost[b * w + s1];
                    if !c.is_finite() {
                        continue;
                    }
                    let i = b * w + s1;
                    let v = c + self.refit_ms[f] + self.trace_ms[b][f - b];
                    if v < next[i] {
                        next[i] = v;
                        at(&mut how, i, BackMove::Refit);
                    }
                    if s1 > 0 {
                        let s = s1 - 1;
                        let i = s * w + b + 1;
                        let v = c + self.refit_ms[f] + self.trace_ms[s][f - s];
                        if v < next[i] {
                            next[i] = v;
                            at(&mut how, i, BackMove::Back);
                        }
                    }
                }
            }
            std::mem::swap(&mut cost, &mut next);
        }
        let (mut i, cost_ms) = cost
            .iter()
            .copied()
            .enumerate()
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .unwrap_or((0, 0.0));
        let mut moves = vec![BackMove::Refit; n + 1];
        moves[0] = BackMove::Rebuild;
        for f in (1..=n).rev() {
            let m = how[f * states + i];
            moves[f] = m;
            let (b, s1) = (i / w, i % w);
            i = match m {
                BackMove::Refit => i,
                // (f, old + 1) came from (old, the cheapest spare then).
                BackMove::Rebuild => (s1 - 1) * w + rebuilt_from[f * (n + 1) + s1 - 1],
                // (s, old + 1) came from (old, s + 1).
                BackMove::Back => (s1 - 1) * w + b + 1,
            };
        }
        BackSchedule { cost_ms, moves }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Costs where trees built at some frames suit the later ones: the trace cost of the tree
    /// built at `b` at frame `f` depends on both, so going back can pay.
    fn costs(n: usize, seed: u64) -> WorkCosts {
        let mut x = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        let mut r = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        WorkCosts {
            refit_ms: (0..=n).map(|_| 0.1 + r()).collect(),
            rebuild_ms: (0..=n).map(|_| 1.0 + 4.0 * r()).collect(),
            trace_ms: (0..=n)
                .map(|b| (b..=n).map(|f| 2.0 + (f - b) as f64 * r()).collect())
                .collect(),
        }
    }

    #[test]
    fn going_back_is_the_exhaustive_optimum_and_never_above_the_plain_oracle() {
        let all = [BackMove::Refit, BackMove::Rebuild, BackMove::Back];
        let mut went_back = 0;
        for seed in 0..80 {
            let n = 1 + seed as usize % 7;
            let c = costs(n, seed);
            let s = c.best_going_back();
            let mut want = f64::INFINITY;
            for code in 0..3usize.pow(n as u32) {
                let mut moves = vec![BackMove::Rebuild];
                moves.extend((0..n).map(|k| all[code / 3usize.pow(k as u32) % 3]));
                if let Some(v) = c.cost_going_back(&moves) {
                    want = want.min(v);
                }
            }
            assert!(
                (s.cost_ms - want).abs() < 1e-9,
                "seed {seed}: {} vs {want}",
                s.cost_ms
            );
            let replayed = c.cost_going_back(&s.moves).expect("a valid schedule");
            assert!((replayed - s.cost_ms).abs() < 1e-9, "seed {seed}");
            assert!(s.cost_ms <= c.best().cost_ms + 1e-9);
            went_back += usize::from(s.moves.contains(&BackMove::Back));
        }
        // The move is used where it pays.
        assert!(went_back > 5, "{went_back}");
    }

    #[test]
    fn past_the_frame_bound_the_oracle_does_not_go_back() {
        let c = costs(BACK_MAX_FRAMES + 1, 3);
        let s = c.best_going_back();
        assert!(!s.moves.contains(&BackMove::Back));
        assert_eq!(s.cost_ms, c.best().cost_ms);
        assert_eq!(c.cost_going_back(&s.moves), Some(s.cost_ms));
    }

    #[test]
    fn going_back_without_a_spare_is_no_schedule() {
        let c = costs(3, 1);
        let moves = [
            BackMove::Rebuild,
            BackMove::Back,
            BackMove::Refit,
            BackMove::Refit,
        ];
        assert_eq!(c.cost_going_back(&moves), None);
    }
}
