//! Refit: recompute every box bottom-up for new primitive positions, topology unchanged.
//!
//! Children are stored after their parent, so one reverse sweep over the nodes sees every child
//! before its parent. Large trees are refitted as parallel subtrees: a subtree's descendants
//! form one contiguous range of nodes, so the ranges of sibling subtrees are disjoint slices.

use super::{Bvh, Node};
use crate::geom::Aabb;

/// Subtrees with at least this many descendant nodes are refitted as parallel tasks.
const PARALLEL_NODES: usize = 1 << 14;

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
        let Some((root, desc)) = self.nodes.split_first_mut() else {
            return;
        };
        if root.is_leaf() {
            root.set_bounds(leaf_bounds(root.first, root.count));
            return;
        }
        refit_desc(desc, 1, &leaf_bounds);
        root.set_bounds(desc[0].bounds().union(desc[1].bounds()));
    }
}

/// Refits the descendants of one interior node: `desc` starts with its children pair, whose
/// global index is `base`, and holds exactly that node's descendants.
fn refit_desc<F: Fn(u32, u32) -> Aabb + Sync>(desc: &mut [Node], base: u32, leaf_bounds: &F) {
    if desc.len() < PARALLEL_NODES {
        refit_sweep(desc, base, leaf_bounds);
        return;
    }
    let (pair, rest) = desc.split_at_mut(2);
    // The left child's descendants come first, then the right child's.
    let right_start = if pair[1].is_leaf() {
        rest.len()
    } else {
        (pair[1].first - base - 2) as usize
    };
    let (ldesc, rdesc) = rest.split_at_mut(right_start);
    let lbase = base + 2;
    let rbase = lbase + right_start as u32;
    let [left, right] = pair else { unreachable!() };
    rayon::join(
        || refit_child(left, ldesc, lbase, leaf_bounds),
        || refit_child(right, rdesc, rbase, leaf_bounds),
    );
}

fn refit_child<F: Fn(u32, u32) -> Aabb + Sync>(
    node: &mut Node,
    desc: &mut [Node],
    base: u32,
    leaf_bounds: &F,
) {
    if node.is_leaf() {
        node.set_bounds(leaf_bounds(node.first, node.count));
    } else {
        refit_desc(desc, base, leaf_bounds);
        node.set_bounds(desc[0].bounds().union(desc[1].bounds()));
    }
}

/// One reverse sweep over a contiguous, closed range of nodes (global index of `nodes[0]` is
/// `base`): every child is met before its parent.
fn refit_sweep<F: Fn(u32, u32) -> Aabb>(nodes: &mut [Node], base: u32, leaf_bounds: &F) {
    for i in (0..nodes.len()).rev() {
        let n = nodes[i];
        let b = if n.is_leaf() {
            leaf_bounds(n.first, n.count)
        } else {
            let c = (n.first - base) as usize;
            nodes[c].bounds().union(nodes[c + 1].bounds())
        };
        nodes[i].set_bounds(b);
    }
}
