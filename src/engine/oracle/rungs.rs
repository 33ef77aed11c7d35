//! The best schedule in hindsight when the rungs between refit and rebuild are moves too
//! (optimise, partial rebuild: `bvh/optimize.rs`, `bvh/partial.rs`).
//!
//! A rung's tree depends on the whole history it restructures, so an exact optimum over every
//! sequence of rungs grows exponentially with the frames. The moves here are: at each frame
//! refit, rebuild, or apply one rung, **at most one rung between two rebuilds**. A tree is then
//! named by its build frame `b` and, once restructured, by the rung `r` and its frame `o`;
//! dynamic programming over those states finds the exact optimum over these moves in
//! `O(R F^3)` for `R` rungs and `F` frames. A policy that restructures twice between rebuilds,
//! or with another budget, makes moves outside this set and may come out below it.

use super::WorkCosts;

/// One rung's costs for one mesh over frames `0 ..= F`, in the modelled measure.
#[derive(Clone, Debug, Default)]
pub struct RungCosts {
    /// `update_ms[b][o - b - 1]`: frame `o`'s update (the refit, then the rung) of the tree
    /// built at `b`, ms.
    pub update_ms: Vec<Vec<f64>>,
    /// `trace_ms[b][o - b - 1][f - o]`: trace cost at frame `f` of the tree built at `b`,
    /// restructured by the rung at `o` and refitted to `f`, ms.
    pub trace_ms: Vec<Vec<Vec<f64>>>,
}

/// One frame's move for one mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Move {
    /// Refit the current tree.
    Refit,
    /// Build a fresh tree.
    Rebuild,
    /// Refit, then apply rung `k` (an index into the rungs).
    Rung(usize),
}

/// The best schedule over refits, rebuilds and rungs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RungSchedule {
    /// Modelled update and trace cost of frames `1 ..= F`, ms.
    pub cost_ms: f64,
    /// The move at each frame `0 ..= F` (frame 0: the initial build).
    pub moves: Vec<Move>,
}

/// A tree's state: built at `b`, and restructured by rung `r` at frame `o` or not.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    Plain(usize),
    Rung(usize, usize, usize),
}

impl WorkCosts {
    /// The modelled cost of frames `1 ..= F` under `moves` (index 0 ignored); `None` when the
    /// schedule applies a second rung before a rebuild (outside the moves of
    /// [`WorkCosts::best_with_rungs`]).
    #[must_use]
    pub fn cost_with_rungs(&self, rungs: &[RungCosts], moves: &[Move]) -> Option<f64> {
        let mut state = State::Plain(0);
        let mut total = 0.0;
        for (f, &m) in moves.iter().enumerate().take(self.frames() + 1).skip(1) {
            total += match (m, state) {
                (Move::Rebuild, _) => {
                    state = State::Plain(f);
                    self.rebuild_ms[f] + self.trace_ms[f][0]
                }
                (Move::Rung(r), State::Plain(b)) => {
                    state = State::Rung(r, b, f);
                    rungs[r].update_ms[b][f - b - 1] + rungs[r].trace_ms[b][f - b - 1][0]
                }
                (Move::Rung(_), State::Rung(..)) => return None,
                (Move::Refit, State::Plain(b)) => self.refit_ms[f] + self.trace_ms[b][f - b],
                (Move::Refit, State::Rung(r, b, o)) => {
                    self.refit_ms[f] + rungs[r].trace_ms[b][o - b - 1][f - o]
                }
            };
        }
        Some(total)
    }

    /// The schedule of least modelled cost over refits, rebuilds and at most one rung between
    /// two rebuilds: exact over those moves (module docs).
    #[must_use]
    pub fn best_with_rungs(&self, rungs: &[RungCosts]) -> RungSchedule {
        let n = self.frames();
        let inf = f64::INFINITY;
        // plain[b]: least cost so far with the tree built at b; rung[r][b][o]: with that tree
        // restructured by rung r at o.
        let mut plain = vec![inf; n + 1];
        plain[0] = 0.0;
        let mut rung = vec![vec![vec![inf; n + 1]; n + 1]; rungs.len()];
        // The state at frame f - 1 a rebuild at f follows.
        let mut parent = vec![State::Plain(0); n + 1];
        for f in 1..=n {
            let (best_state, best) = best_of(&plain, &rung, f);
            for (r, rc) in rungs.iter().enumerate() {
                for b in 0..f {
                    // Those already restructured refit; the plain ones may take the rung now.
                    for (o, c) in rung[r][b].iter_mut().enumerate().take(f).skip(b + 1) {
                        if c.is_finite() {
                            *c += self.refit_ms[f] + rc.trace_ms[b][o - b - 1][f - o];
                        }
                    }
                    if plain[b].is_finite() {
                        rung[r][b][f] =
                            plain[b] + rc.update_ms[b][f - b - 1] + rc.trace_ms[b][f - b - 1][0];
                    }
                }
            }
            for (b, c) in plain.iter_mut().enumerate().take(f) {
                if c.is_finite() {
                    *c += self.refit_ms[f] + self.trace_ms[b][f - b];
                }
            }
            plain[f] = best + self.rebuild_ms[f] + self.trace_ms[f][0];
            parent[f] = best_state;
        }
        let (mut state, cost_ms) = best_of(&plain, &rung, n + 1);
        let mut moves = vec![Move::Refit; n + 1];
        loop {
            let b = match state {
                State::Plain(b) => b,
                State::Rung(r, b, o) => {
                    moves[o] = Move::Rung(r);
                    b
                }
            };
            moves[b] = Move::Rebuild;
            if b == 0 {
                break;
            }
            state = parent[b];
        }
        RungSchedule { cost_ms, moves }
    }
}

/// The least-cost state among the trees built before frame `f` (the first found on ties).
fn best_of(plain: &[f64], rung: &[Vec<Vec<f64>>], f: usize) -> (State, f64) {
    let mut best = (State::Plain(0), f64::INFINITY);
    for (b, &c) in plain.iter().enumerate().take(f) {
        if c < best.1 {
            best = (State::Plain(b), c);
        }
    }
    for (r, by_b) in rung.iter().enumerate() {
        for (b, by_o) in by_b.iter().enumerate().take(f) {
            for (o, &c) in by_o.iter().enumerate().take(f).skip(b + 1) {
                if c < best.1 {
                    best = (State::Rung(r, b, o), c);
                }
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mesh whose refitted tree degrades by `grow` a frame, over `n` frames, with one rung
    /// that halves the degradation.
    fn costs(n: usize, grow: f64, rebuild: f64, rung_cost: f64) -> (WorkCosts, Vec<RungCosts>) {
        let fresh = |f: usize| 10.0 + (f % 3) as f64;
        let trace_ms = (0..=n)
            .map(|b| {
                (b..=n)
                    .map(|f| fresh(f) * (1.0 + grow * (f - b) as f64))
                    .collect()
            })
            .collect();
        let w = WorkCosts {
            refit_ms: vec![1.0; n + 1],
            rebuild_ms: vec![rebuild; n + 1],
            trace_ms,
        };
        let rc = RungCosts {
            update_ms: (0..=n)
                .map(|b| (b + 1..=n).map(|_| 1.0 + rung_cost).collect())
                .collect(),
            trace_ms: (0..=n)
                .map(|b| {
                    (b + 1..=n)
                        .map(|o| {
                            (o..=n)
                                .map(|f| {
                                    let age = (o - b) as f64 * 0.5 + (f - o) as f64;
                                    fresh(f) * (1.0 + grow * age)
                                })
                                .collect()
                        })
                        .collect()
                })
                .collect(),
        };
        (w, vec![rc])
    }

    /// Every schedule of `n` frames over refit, rebuild and the rungs, in order.
    fn every_schedule(n: usize, rungs: usize) -> Vec<Vec<Move>> {
        let choices: Vec<Move> = [Move::Refit, Move::Rebuild]
            .into_iter()
            .chain((0..rungs).map(Move::Rung))
            .collect();
        let mut all = vec![vec![Move::Rebuild]];
        for _ in 0..n {
            all = all
                .into_iter()
                .flat_map(|s| {
                    choices.iter().map(move |&m| {
                        let mut t = s.clone();
                        t.push(m);
                        t
                    })
                })
                .collect();
        }
        all
    }

    #[test]
    fn the_best_schedule_is_the_least_of_every_schedule_in_its_moves() {
        for (grow, rebuild, rung_cost) in [
            (0.05, 8.0, 1.0),
            (0.2, 8.0, 1.0),
            (0.2, 30.0, 2.0),
            (0.02, 30.0, 0.1),
            (0.3, 3.0, 5.0),
        ] {
            let (w, rungs) = costs(7, grow, rebuild, rung_cost);
            let best = w.best_with_rungs(&rungs);
            let costs: Vec<f64> = every_schedule(7, 1)
                .iter()
                .filter_map(|s| w.cost_with_rungs(&rungs, s))
                .collect();
            let least = costs.iter().copied().fold(f64::INFINITY, f64::min);
            assert!(
                (best.cost_ms - least).abs() < 1e-9,
                "{grow} {rebuild} {rung_cost}: {} against {least}",
                best.cost_ms
            );
            assert_eq!(w.cost_with_rungs(&rungs, &best.moves), Some(best.cost_ms));
            // Without the rung, the same as the refit-or-rebuild oracle.
            assert!((w.best_with_rungs(&[]).cost_ms - w.best().cost_ms).abs() < 1e-9);
        }
    }

    #[test]
    fn a_cheap_rung_that_wins_is_taken_and_a_second_is_outside_the_moves() {
        let (w, rungs) = costs(7, 0.2, 30.0, 0.1);
        let best = w.best_with_rungs(&rungs);
        assert!(best.moves.contains(&Move::Rung(0)), "{:?}", best.moves);
        assert!(best.cost_ms < w.best().cost_ms);
        let mut twice = vec![Move::Refit; 8];
        twice[0] = Move::Rebuild;
        twice[2] = Move::Rung(0);
        twice[4] = Move::Rung(0);
        assert_eq!(w.cost_with_rungs(&rungs, &twice), None);
    }
}
