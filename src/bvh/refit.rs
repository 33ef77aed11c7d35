//! Refit: recompute every box bottom-up for new primitive positions, topology unchanged.
//!
//! Children are stored after their parent, so one reverse sweep over the nodes sees every child
//! before its parent. Large trees are refitted as subtrees (in parallel when there are several
//! threads): a subtree's descendants form one contiguous range of nodes and its leaves one
//! contiguous range of primitive slots, so the ranges of sibling subtrees are disjoint slices.
//! Per-slot data (a mesh's triangles in leaf order) is updated for a whole subtree (on one
//! thread: the whole tree) in one pass over its slots before its sweep, which then bounds each
//! leaf from the updated data. The update's scattered reads thus run in a plain forward loop,
//! which can prefetch far ahead, instead of in the sweep, which branches at every node; the
//! sweep reads the slots back roughly last-written first, so the part written last is still in
//! the last-level cache.

use super::{Bvh, Node};
use crate::geom::Aabb;

/// On several threads, subtrees with at least this many descendant nodes (or an eighth of a
/// thread's share, when more) are split into their two children's subtrees, refitted as
/// parallel tasks; smaller ones are updated and swept by one task. One thread updates and
/// sweeps the whole tree at once: splitting it costs more in task overhead than the smaller
/// subtrees win by staying in the cache between update and sweep (`docs/build_speed.md`).
const PARALLEL_NODES: usize = 1 << 14;

/// What a refit does at the slots and leaves of a tree.
pub(crate) trait LeafRefit<T>: Sync {
    /// Updates the per-slot entries of a subtree before any of its leaves is bounded: `data` is
    /// `slot_data[first .. first + data.len()]`, or an empty slice when there is none.
    #[inline(always)]
    fn update(&self, data: &mut [T], first: u32) {
        let _ = (data, first);
    }

    /// The new box of the leaf over slots `first .. first + count`; `data` is its (updated)
    /// entries, or an empty slice.
    fn leaf(&self, data: &[T], first: u32, count: u32) -> Aabb;
}

/// Leaf boxes from a closure, without per-slot data.
struct LeafFn<F>(F);

impl<T, F: Fn(u32, u32) -> Aabb + Sync> LeafRefit<T> for LeafFn<F> {
    #[inline(always)]
    fn leaf(&self, _: &[T], first: u32, count: u32) -> Aabb {
        (self.0)(first, count)
    }
}

impl Bvh {
    /// Refits the tree for new primitive boxes; `prim_bounds(id)` gives primitive `id`'s box.
    pub fn refit(&mut self, prim_bounds: impl Fn(u32) -> Aabb + Sync) {
        let prims = std::mem::take(&mut self.prim_indices);
        self.refit_leaves(|first, count| {
            prims[first as usize..(first + count) as usize]
                .iter()
                .fold(Aabb::EMPTY, |b, &p| b.union(prim_bounds(p)))
        });
        self.prim_indices = prims;
    }

    /// Refits the tree given each leaf's new box: `leaf_bounds(first, count)` bounds the
    /// primitives in slots `first .. first + count`. No allocation.
    pub fn refit_leaves(&mut self, leaf_bounds: impl Fn(u32, u32) -> Aabb + Sync) {
        self.refit_with(&mut [(); 0], &LeafFn(leaf_bounds));
    }

    /// Refits the tree while updating per-slot data: `slot_data` is empty or has one entry per
    /// primitive slot. Every slot is passed to `leaf.update` once (in runs of consecutive slots,
    /// a subtree's) before `leaf.leaf` bounds the leaves holding it; every leaf is bounded once.
    /// Disjoint subtrees may be done in parallel. No allocation.
    pub(crate) fn refit_with<T: Send>(&mut self, slot_data: &mut [T], leaf: &impl LeafRefit<T>) {
        debug_assert!(slot_data.is_empty() || slot_data.len() == self.prim_indices.len());
        let Some((root, desc)) = self.nodes.split_first_mut() else {
            return;
        };
        let mut data = SlotData {
            data: slot_data,
            first: 0,
        };
        if root.is_leaf() {
            refit_leaf(root, &mut data, leaf);
            return;
        }
        let threads = rayon::current_num_threads();
        let split = if threads > 1 {
            PARALLEL_NODES.max(desc.len() / (8 * threads))
        } else {
            usize::MAX
        };
        refit_desc(desc, 1, &mut data, leaf, split);
        root.set_bounds(desc[0].bounds().union(desc[1].bounds()));
    }
}

/// The per-slot data of one subtree: its slots start at `first`.
struct SlotData<'a, T> {
    data: &'a mut [T],
    first: u32,
}

impl<T> SlotData<'_, T> {
    /// A leaf's entries (empty when there is no per-slot data).
    #[inline(always)]
    fn leaf(&self, first: u32, count: u32) -> &[T] {
        if self.data.is_empty() {
            return &[];
        }
        let at = (first - self.first) as usize;
        &self.data[at..at + count as usize]
    }

    /// Splits off the slots from global slot `at` on.
    fn split_at(&mut self, at: u32) -> (SlotData<'_, T>, SlotData<'_, T>) {
        let k = if self.data.is_empty() {
            0
        } else {
            (at - self.first) as usize
        };
        let (l, r) = self.data.split_at_mut(k);
        (
            SlotData {
                data: l,
                first: self.first,
            },
            SlotData { data: r, first: at },
        )
    }
}

/// The first primitive slot of the subtree rooted at `node`, whose descendants are `desc`
/// (global index of `desc[0]` is `base`): its leftmost leaf's.
fn first_slot(node: &Node, desc: &[Node], base: u32) -> u32 {
    let mut n = *node;
    while !n.is_leaf() {
        n = desc[(n.first - base) as usize];
    }
    n.first
}

/// Refits the descendants of one interior node: `desc` starts with its children pair, whose
/// global index is `base`, and holds exactly that node's descendants; `data` holds its slots.
/// Ranges of at least `split` nodes are split between the two children.
fn refit_desc<T: Send, F: LeafRefit<T>>(
    desc: &mut [Node],
    base: u32,
    data: &mut SlotData<'_, T>,
    leaf: &F,
    split: usize,
) {
    if desc.len() < split {
        refit_sweep(desc, base, data, leaf);
        return;
    }
    let (pair, rest) = desc.split_at_mut(2);
    // The left child's descendants come first, then the right child's.
    let right_start = if pair[1].is_leaf() {
        rest.len()
    } else {
        (pair[1].first - base - 2) as usize
    };
    let lbase = base + 2;
    let rbase = lbase + right_start as u32;
    let rfirst = first_slot(&pair[1], rest, lbase);
    let (ldesc, rdesc) = rest.split_at_mut(right_start);
    let (mut ldata, mut rdata) = data.split_at(rfirst);
    let [left, right] = pair else { unreachable!() };
    rayon::join(
        || refit_child(left, ldesc, lbase, &mut ldata, leaf, split),
        || refit_child(right, rdesc, rbase, &mut rdata, leaf, split),
    );
}

fn refit_child<T: Send, F: LeafRefit<T>>(
    node: &mut Node,
    desc: &mut [Node],
    base: u32,
    data: &mut SlotData<'_, T>,
    leaf: &F,
    split: usize,
) {
    if node.is_leaf() {
        refit_leaf(node, data, leaf);
    } else {
        refit_desc(desc, base, data, leaf, split);
        node.set_bounds(desc[0].bounds().union(desc[1].bounds()));
    }
}

/// Refits a leaf whose slots are exactly `data`'s.
fn refit_leaf<T, F: LeafRefit<T>>(node: &mut Node, data: &mut SlotData<'_, T>, leaf: &F) {
    leaf.update(data.data, data.first);
    node.set_bounds(leaf.leaf(data.leaf(node.first, node.count), node.first, node.count));
}

/// Updates the slots of a subtree, then one reverse sweep over its nodes, a contiguous, closed
/// range (global index of `nodes[0]` is `base`) whose slots are exactly `data`'s: every child
/// is met before its parent.
fn refit_sweep<T, F: LeafRefit<T>>(
    nodes: &mut [Node],
    base: u32,
    data: &mut SlotData<'_, T>,
    leaf: &F,
) {
    leaf.update(data.data, data.first);
    for i in (0..nodes.len()).rev() {
        let n = nodes[i];
        let b = if n.is_leaf() {
            leaf.leaf(data.leaf(n.first, n.count), n.first, n.count)
        } else {
            let c = (n.first - base) as usize;
            nodes[c].bounds().union(nodes[c + 1].bounds())
        };
        nodes[i].set_bounds(b);
    }
}
