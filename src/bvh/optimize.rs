//! Insertion-based optimisation (Bittner, Hapala & Havran 2013): take out the interior nodes
//! that cost most and reinsert their children where they cost least, on a refitted tree or a
//! fresh one. Leaves are never split or merged, so the result is a valid tree over the same
//! leaves; it is written back in the builders' layout ([`super::topology`]).
//!
//! A node is chosen by the paper's combined measure `A(n) * A(n) / (A(l) + A(r)) * A(n) /
//! min(A(l), A(r))` (large boxes over small, unbalanced children: what refitting moving parts
//! makes). The node and its parent leave the tree (the sibling takes the parent's place) and
//! the node's two children are inserted again one by one, each as the sibling of the node that
//! minimises the increase of the summed areas, found by branch and bound over the tree
//! (section 4.2): the cost of inserting box `b` beside `x` is `A(x ∪ b)` plus the growth
//! `A(y ∪ b) - A(y)` of every ancestor `y` of `x`, a bound that only grows going down. Where
//! the paper keeps every move, a move that does not lower the summed areas is undone here,
//! so the SAH never grows.

use super::MeshBvh;
use super::topology::{NONE, RestructureWorkspace, Topology};
use crate::geom::Aabb;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// How much an optimisation may do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OptimizeBudget {
    /// Share of the interior nodes taken out and reinserted per pass (0 ..= 1).
    pub share: f32,
    /// Passes (each picks its nodes anew).
    pub passes: u32,
    /// Most candidate positions one insertion looks at (bounds the search on bad trees).
    pub max_visits: u32,
}

impl Default for OptimizeBudget {
    fn default() -> Self {
        Self {
            share: 0.01,
            passes: 1,
            max_visits: 4096,
        }
    }
}

/// What an optimisation did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OptimizeStats {
    /// Nodes taken out and reinserted elsewhere.
    pub moved: u32,
    /// Candidate positions the searches looked at.
    pub visits: u64,
    /// How much the summed half areas of the interior nodes (the SAH's numerator with
    /// constants 1) went down.
    pub gain: f64,
}

/// Scratch of the insertion search, kept between calls.
#[derive(Clone, Debug, Default)]
pub struct OptimizeScratch {
    picks: Vec<(f32, u32)>,
    heap: BinaryHeap<Candidate>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Candidate {
    /// Lower bound of any insertion at or below `node`: the induced cost plus the new box's area.
    bound: f32,
    /// Growth of the ancestors' areas above `node`.
    induced: f32,
    node: u32,
}

impl OptimizeScratch {
    /// Bytes held.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        crate::bvh::held(&self.picks) + self.heap.capacity() * std::mem::size_of::<Candidate>()
    }

    /// Reserves the search's queue for `budget` (it holds at most two entries per visit).
    pub fn reserve(&mut self, budget: OptimizeBudget) {
        let want = 2 * budget.max_visits as usize + 2;
        if self.heap.capacity() < want {
            self.heap.reserve(want - self.heap.len());
        }
    }
}

impl Eq for Candidate {}

impl Ord for Candidate {
    fn cmp(&self, o: &Self) -> Ordering {
        // Smallest bound first.
        o.bound.total_cmp(&self.bound)
    }
}

impl PartialOrd for Candidate {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

impl Topology {
    /// Optimises in place within `budget` (see the module docs).
    pub fn optimize(&mut self, budget: OptimizeBudget, s: &mut OptimizeScratch) -> OptimizeStats {
        let mut stats = OptimizeStats::default();
        // Every interior node has two children and every id is in the tree: one more leaf
        // than interior nodes.
        let interior = self.len() / 2;
        let k = ((interior as f64 * f64::from(budget.share.clamp(0.0, 1.0))).ceil() as usize)
            .min(interior);
        for _ in 0..budget.passes {
            if k == 0 {
                break;
            }
            self.pick(k, &mut s.picks);
            for i in 0..s.picks.len() {
                let n = s.picks[i].1;
                let (moved, visits) = self.reinsert(n, budget.max_visits, &mut s.heap);
                stats.visits += u64::from(visits);
                if let Some(gain) = moved {
                    stats.moved += 1;
                    stats.gain += f64::from(gain);
                }
            }
        }
        stats
    }

    /// The `k` reachable interior nodes but the root with the largest combined measure, into
    /// `picks`.
    fn pick(&self, k: usize, picks: &mut Vec<(f32, u32)>) {
        match self.loaded_areas() {
            Some(areas) => self.pick_by(k, picks, |n| areas[n as usize]),
            None => self.pick_by(k, picks, |n| self.area(n)),
        }
    }

    /// [`Topology::pick`] with the half areas `area`.
    #[inline(always)]
    fn pick_by(&self, k: usize, picks: &mut Vec<(f32, u32)>, area: impl Fn(u32) -> f32) {
        picks.clear();
        for n in 0..self.len() as u32 {
            // Interior and not the root (unreachable ids have no parent either).
            if self.is_leaf(n) || self.parent[n as usize] == NONE {
                continue;
            }
            let [l, r] = self.child[n as usize];
            let (a, al, ar) = (area(n), area(l), area(r));
            let m = if al + ar > 0.0 && al.min(ar) > 0.0 {
                a * (a / (al + ar)) * (a / al.min(ar))
            } else {
                a
            };
            picks.push((m, n));
        }
        if picks.len() > k {
            picks.select_nth_unstable_by(k, |a, b| b.0.total_cmp(&a.0));
            picks.truncate(k);
        }
        // Worst first, and the same order on every run.
        picks.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    }

    /// Takes node `n` out of the tree with its parent (the sibling takes the parent's place)
    /// and inserts `n`'s two children apart, each where it costs least, with the two freed
    /// nodes as their new parents. If the summed areas did not go down, every step is undone
    /// in reverse (the boxes come back exactly: they are unions). Returns how much they went
    /// down when the tree changed.
    fn reinsert(
        &mut self,
        n: u32,
        max_visits: u32,
        heap: &mut BinaryHeap<Candidate>,
    ) -> (Option<f32>, u32) {
        let p = self.parent[n as usize];
        if p == NONE || self.is_leaf(n) {
            return (None, 0);
        }
        let sibling = self.child[p as usize][1 - self.side(n)];
        let [l, r] = self.child[n as usize];
        let scale = self.area(p);
        // Out go `n` and `p`: their areas leave the sum, the ancestors may shrink.
        let mut delta = -self.area(n) - self.area(p) + self.detach(n);
        // The larger child first (it has fewer good places).
        let (a, b) = if self.area(l) >= self.area(r) {
            (l, r)
        } else {
            (r, l)
        };
        let mut visits = 0;
        for (x, free) in [(a, p), (b, n)] {
            let bx = self.bounds[x as usize];
            let (best, cost, v) = self.best_sibling(bx, bx.half_area(), max_visits, heap);
            visits += v;
            self.insert(x, free, best);
            delta += cost;
        }
        if -delta > MIN_GAIN * scale {
            return (Some(-delta), visits);
        }
        // Undo: take the children out again, rejoin them under `n`, put `n` back beside its
        // old sibling under `p`.
        self.detach(b);
        self.detach(a);
        self.child[n as usize] = [l, r];
        self.parent[l as usize] = n;
        self.parent[r as usize] = n;
        self.bounds[n as usize] = self.bounds[l as usize].union(self.bounds[r as usize]);
        self.touch(n);
        self.insert(n, p, sibling);
        (None, visits)
    }

    /// Takes the subtree at `x` out of the tree: its parent leaves too and `x`'s sibling
    /// takes the parent's place. Returns how much the summed areas of the remaining
    /// ancestors changed (zero or less).
    fn detach(&mut self, x: u32) -> f32 {
        let p = self.parent[x as usize];
        let sibling = self.child[p as usize][1 - self.side(x)];
        let g = self.parent[p as usize];
        self.parent[x as usize] = NONE;
        if g == NONE {
            self.root = sibling;
            self.parent[sibling as usize] = NONE;
            return 0.0;
        }
        let side = self.side(p);
        self.link(g, side, sibling);
        let mut delta = 0.0;
        let mut y = g;
        while y != NONE {
            let [c0, c1] = self.child[y as usize];
            let before = self.area(y);
            self.bounds[y as usize] = self.bounds[c0 as usize].union(self.bounds[c1 as usize]);
            self.touch(y);
            delta += self.area(y) - before;
            y = self.parent[y as usize];
        }
        delta
    }

    /// Inserts subtree `x` as the sibling of `best`, with `free` (an unused interior id) as
    /// their new parent.
    fn insert(&mut self, x: u32, free: u32, best: u32) {
        let b = self.bounds[x as usize];
        let gp = self.parent[best as usize];
        self.bounds[free as usize] = self.bounds[best as usize].union(b);
        self.child[free as usize] = [best, x];
        self.touch(free);
        if gp == NONE {
            self.root = free;
            self.parent[free as usize] = NONE;
        } else {
            let side = self.side(best);
            self.link(gp, side, free);
        }
        self.parent[best as usize] = free;
        self.parent[x as usize] = free;
        self.refit_up(gp);
    }

    /// Branch and bound for the node beside which box `b` (half area `ab`) costs least.
    fn best_sibling(
        &self,
        b: Aabb,
        ab: f32,
        max_visits: u32,
        heap: &mut BinaryHeap<Candidate>,
    ) -> (u32, f32, u32) {
        heap.clear();
        heap.push(Candidate {
            bound: ab,
            induced: 0.0,
            node: self.root,
        });
        let (mut best, mut best_cost) = (self.root, f32::INFINITY);
        let mut visits = 0;
        while let Some(c) = heap.pop() {
            if c.bound >= best_cost || visits >= max_visits {
                break;
            }
            visits += 1;
            let joined = self.bounds[c.node as usize].union(b).half_area();
            let direct = joined + c.induced;
            if direct < best_cost {
                best_cost = direct;
                best = c.node;
            }
            if !self.is_leaf(c.node) {
                let induced = c.induced + joined - self.area(c.node);
                let bound = induced + ab;
                if bound < best_cost {
                    for &k in &self.child[c.node as usize] {
                        heap.push(Candidate {
                            bound,
                            induced,
                            node: k,
                        });
                    }
                }
            }
        }
        (best, best_cost, visits)
    }
}

/// Relative gain below which a subtree stays where it is (rounding would otherwise move
/// subtrees back and forth for nothing).
const MIN_GAIN: f32 = 1e-4;

impl MeshBvh {
    /// Optimises the tree in place (see the module docs) and writes it back; the triangles move
    /// with their leaves. Allocates nothing once `ws` and `s` have grown to the tree's size.
    /// Leaves the tree as it was when the result would be deeper than [`super::MAX_DEPTH`]
    /// (then `moved` is 0).
    pub fn optimize(
        &mut self,
        budget: OptimizeBudget,
        ws: &mut RestructureWorkspace,
        s: &mut OptimizeScratch,
    ) -> OptimizeStats {
        if self.bvh.nodes.len() < 5 {
            return OptimizeStats::default();
        }
        ws.topo.load(&self.bvh);
        let stats = ws.topo.optimize(budget, s);
        // Every move that stayed lowered the summed areas; none stayed: the tree is unchanged.
        if stats.moved == 0 {
            return stats;
        }
        if self.apply_topology(ws) {
            stats
        } else {
            OptimizeStats::default()
        }
    }
}
