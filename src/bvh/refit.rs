//! Refit: recompute every box bottom-up for new primitive positions, topology unchanged.
//!
//! Children are stored after their parent, so one reverse sweep over the nodes sees every child
//! before its parent. Large trees are refitted as parallel subtrees: a subtree's descendants
//! form one contiguous range of nodes, so the ranges of sibling subtrees are disjoint slices.

use super::{Bvh, Node};
use crate::geom::Aabb;

/// Subtrees with at least this many descendant nodes are refitted as parallel tasks.
const PARALLEL_NODES: usize = 1 << 14;
/// How many nodes ahead of the sweep a leaf is announced to [`LeafRefit::prefetch`] (about
/// half of the nodes are leaves: some 30 leaves, 50 triangles, at a leaf size of 4).
const PREFETCH_NODES: usize = 64;

/// What a refit does at a leaf.
pub(crate) trait LeafRefit<T>: Sync {
    /// Updates a leaf's per-slot entries `data` (`slot_data[first .. first + count]`, or an
    /// empty slice) and returns the leaf's new box.
    fn leaf(&self, data: &mut [T], first: u32, count: u32) -> Aabb;

    /// Called a few dozen nodes before the sweep reaches the leaf over slots
    /// `first .. first + count`, to start loading what [`LeafRefit::leaf`] will read. A hint:
    /// not every leaf is announced, and a leaf may be announced more than once (`count` is 0
    /// before the first leaf).
    #[inline(always)]
    fn prefetch(&self, first: u32, count: u32) {
        let _ = (first, count);
    }
}

/// A leaf refit from a closure, without prefetching.
struct LeafFn<F>(F);

impl<T, F: Fn(&mut [T], u32, u32) -> Aabb + Sync> LeafRefit<T> for LeafFn<F> {
    #[inline(always)]
    fn leaf(&self, data: &mut [T], first: u32, count: u32) -> Aabb {
        (self.0)(data, first, count)
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
        self.refit_with(
            &mut [(); 0],
            &LeafFn(|_: &mut [()], first, count| leaf_bounds(first, count)),
        );
    }

    /// Refits the tree while updating per-slot data: `slot_data` is empty or has one entry per
    /// primitive slot, and `leaf.leaf(data, first, count)` gets a leaf's entries
    /// (`slot_data[first .. first + count]`, or an empty slice) to update, and returns the
    /// leaf's new box. Every leaf is visited once; leaves of disjoint subtrees may be visited
    /// in parallel. No allocation.
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
            root.set_bounds(leaf.leaf(data.leaf(root.first, root.count), root.first, root.count));
            return;
        }
        refit_desc(desc, 1, &mut data, leaf);
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
    fn leaf(&mut self, first: u32, count: u32) -> &mut [T] {
        if self.data.is_empty() {
            return &mut [];
        }
        let at = (first - self.first) as usize;
        &mut self.data[at..at + count as usize]
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
fn refit_desc<T: Send, F: LeafRefit<T>>(
    desc: &mut [Node],
    base: u32,
    data: &mut SlotData<'_, T>,
    leaf: &F,
) {
    if desc.len() < PARALLEL_NODES {
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
        || refit_child(left, ldesc, lbase, &mut ldata, leaf),
        || refit_child(right, rdesc, rbase, &mut rdata, leaf),
    );
}

fn refit_child<T: Send, F: LeafRefit<T>>(
    node: &mut Node,
    desc: &mut [Node],
    base: u32,
    data: &mut SlotData<'_, T>,
    leaf: &F,
) {
    if node.is_leaf() {
        node.set_bounds(leaf.leaf(data.leaf(node.first, node.count), node.first, node.count));
    } else {
        refit_desc(desc, base, data, leaf);
        node.set_bounds(desc[0].bounds().union(desc[1].bounds()));
    }
}

/// One reverse sweep over a contiguous, closed range of nodes (global index of `nodes[0]` is
/// `base`): every child is met before its parent. Leaves are announced
/// [`PREFETCH_NODES`] nodes ahead.
fn refit_sweep<T, F: LeafRefit<T>>(
    nodes: &mut [Node],
    base: u32,
    data: &mut SlotData<'_, T>,
    leaf: &F,
) {
    // The leaf announced last: an interior node ahead announces it again (rather than a
    // branch on whether the node ahead is a leaf, which would often be mispredicted).
    let mut announced = (0, 0);
    for i in (0..nodes.len()).rev() {
        if let Some(ahead) = i.checked_sub(PREFETCH_NODES) {
            let a = nodes[ahead];
            announced = if a.is_leaf() {
                (a.first, a.count)
            } else {
                announced
            };
            leaf.prefetch(announced.0, announced.1);
        }
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
