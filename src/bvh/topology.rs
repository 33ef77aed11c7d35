//! A tree's topology in linked form (children and parent per node), for the optimisation
//! ([`super::optimize`]), which moves single nodes; written back in the builders' layout, so
//! that refit and traversal work on the result unchanged. (The partial rebuild, which moves
//! whole subtrees, writes its tree directly; it shares [`RestructureWorkspace`]'s buffers.)
//!
//! Write-back lays the reachable nodes out depth first: a node's two children are allocated
//! together, then the left child's descendants, then the right's, so every node's children are
//! adjacent and after it and every subtree owns one range of nodes and one of primitive slots.
//! Leaves keep their primitives; the new slot order is returned as runs of old slots. A subtree
//! no change reached (no link or box below it changed: `Topology::touch` marks every node a
//! change passes) is already laid out so in the loaded tree, so it is copied as one block of
//! nodes with their indices shifted and one run of slots: an optimisation that moves a few
//! hundred nodes rewrites the paths above them, not the whole tree.

use super::node::descendants_end;
use super::{Bvh, MAX_DEPTH, MeshBvh, Node};
use crate::geom::Aabb;
use glam::Vec3;

/// Marks "no node" (a leaf's children, the root's parent).
pub(crate) const NONE: u32 = u32::MAX;

/// A tree in linked form: node `i` has box `bounds[i]`; interior nodes have `child[i]`, leaves
/// `child[i] == [NONE; 2]` and the primitive slots they have in the tree it was loaded from
/// (leaves are never changed). Nodes not reachable from `root` are unused.
#[derive(Clone, Debug, Default)]
pub struct Topology {
    pub(crate) bounds: Vec<Aabb>,
    pub(crate) child: Vec<[u32; 2]>,
    pub(crate) parent: Vec<u32>,
    pub(crate) root: u32,
    /// Write-back stack: (node, position, depth).
    stack: Vec<(u32, u32, u32)>,
    /// Nodes a change passed since the load ([`Topology::touch`]): their subtrees differ
    /// from the loaded tree's.
    touched: Vec<bool>,
    /// Each node's height in the loaded tree (0 for a leaf): a copied subtree's.
    height: Vec<u8>,
    /// Each node's half area as loaded, while no change has been made since
    /// ([`Topology::loaded_areas`]).
    areas: Vec<f32>,
    unchanged: bool,
}

/// Nodes from which [`Topology::load`] runs on two threads.
const PARALLEL_LOAD: usize = 1 << 15;

impl Topology {
    /// Loads `bvh`'s topology (node ids are its node indices). Allocates only to grow. On
    /// several threads for large trees: the boxes and areas on one, the links and heights on
    /// another.
    pub fn load(&mut self, bvh: &Bvh) {
        let nodes = bvh.nodes();
        let Self {
            bounds,
            child,
            parent,
            touched,
            height,
            areas,
            ..
        } = self;
        let mut boxes = || {
            bounds.clear();
            bounds.extend(nodes.iter().map(Node::bounds));
            areas.clear();
            areas.extend(bounds.iter().map(Aabb::half_area));
        };
        let mut links = || {
            child.clear();
            child.extend(nodes.iter().map(|n| {
                if n.is_leaf() {
                    [NONE; 2]
                } else {
                    [n.first, n.first + 1]
                }
            }));
            parent.clear();
            parent.resize(nodes.len(), NONE);
            height.clear();
            height.resize(nodes.len(), 0);
            // Children after parents: in reverse, a node's children are done before it.
            for (i, n) in nodes.iter().enumerate().rev() {
                if !n.is_leaf() {
                    let c = n.first as usize;
                    parent[c] = i as u32;
                    parent[c + 1] = i as u32;
                    // A valid tree is at most `MAX_DEPTH` deep, which fits.
                    height[i] = height[c].max(height[c + 1]).saturating_add(1);
                }
            }
            touched.clear();
            touched.resize(nodes.len(), false);
        };
        if nodes.len() >= PARALLEL_LOAD && rayon::current_num_threads() > 1 {
            rayon::join(boxes, links);
        } else {
            boxes();
            links();
        }
        self.root = 0;
        self.unchanged = true;
    }

    /// The half areas of the nodes as loaded, while the tree is as loaded.
    pub(crate) fn loaded_areas(&self) -> Option<&[f32]> {
        self.unchanged.then_some(self.areas.as_slice())
    }

    /// Marks `n` as changed: its subtree is written node by node.
    #[inline]
    pub(crate) fn touch(&mut self, n: u32) {
        self.touched[n as usize] = true;
        self.unchanged = false;
    }

    /// Number of node ids (reachable or not).
    #[must_use]
    pub fn len(&self) -> usize {
        self.bounds.len()
    }

    /// True when there is no node.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.bounds.is_empty()
    }

    /// True for a leaf.
    #[inline]
    pub(crate) fn is_leaf(&self, n: u32) -> bool {
        self.child[n as usize][0] == NONE
    }

    /// Half the surface area of `n`'s box.
    #[inline]
    pub(crate) fn area(&self, n: u32) -> f32 {
        self.bounds[n as usize].half_area()
    }

    /// Makes `c` the `side` child of `p`.
    #[inline]
    pub(crate) fn link(&mut self, p: u32, side: usize, c: u32) {
        self.child[p as usize][side] = c;
        self.parent[c as usize] = p;
        self.touch(p);
    }

    /// Which child of its parent `n` is (0 or 1).
    #[inline]
    pub(crate) fn side(&self, n: u32) -> usize {
        let p = self.parent[n as usize];
        usize::from(self.child[p as usize][1] == n)
    }

    /// Recomputes the boxes from `n` up to the root.
    pub(crate) fn refit_up(&mut self, mut n: u32) {
        while n != NONE {
            let [a, b] = self.child[n as usize];
            if a != NONE {
                self.bounds[n as usize] = self.bounds[a as usize].union(self.bounds[b as usize]);
            }
            self.touch(n);
            n = self.parent[n as usize];
        }
    }

    /// Writes the reachable tree into `nodes` in the builders' layout (`loaded`: the nodes it
    /// was loaded from, whose untouched subtrees are copied as blocks), and into `runs` the old
    /// primitive slots of the new ones in order, as runs `[first, count]`. Returns false
    /// (writing nothing) when the tree is deeper than [`MAX_DEPTH`]. Allocates only to grow.
    pub(crate) fn write(
        &mut self,
        loaded: &Bvh,
        nodes: &mut Vec<Node>,
        runs: &mut Vec<[u32; 2]>,
    ) -> bool {
        nodes.clear();
        runs.clear();
        if self.bounds.is_empty() {
            return true;
        }
        let mut stack = std::mem::take(&mut self.stack);
        stack.clear();
        stack.push((self.root, 0, 0));
        nodes.push(Node::default());
        let mut slots = 0u32;
        let mut ok = true;
        while let Some((n, pos, depth)) = stack.pop() {
            if depth as usize > MAX_DEPTH {
                ok = false;
                break;
            }
            let b = self.bounds[n as usize];
            if self.is_leaf(n) {
                let Node { first, count, .. } = loaded.nodes[n as usize];
                nodes[pos as usize] = Node::leaf(b, slots, count);
                push_run(runs, first, count);
                slots += count;
            } else if !self.touched[n as usize]
                && (depth + u32::from(self.height[n as usize])) as usize <= MAX_DEPTH
            {
                // As loaded: its descendants and slots are one range each there.
                let (lo, count) = loaded.slot_range(n);
                let first = loaded.nodes[n as usize].first;
                let end = descendants_end(&loaded.nodes, n as usize);
                let q = nodes.len() as u32;
                nodes[pos as usize] = Node::interior(b, q);
                let shift_node = q.wrapping_sub(first);
                let shift_slot = slots.wrapping_sub(lo);
                nodes.extend(loaded.nodes[first as usize..end].iter().map(|&m| {
                    let shift = if m.is_leaf() { shift_slot } else { shift_node };
                    Node {
                        first: m.first.wrapping_add(shift),
                        ..m
                    }
                }));
                push_run(runs, lo, count);
                slots += count;
            } else {
                let q = nodes.len() as u32;
                nodes.push(Node::default());
                nodes.push(Node::default());
                nodes[pos as usize] = Node::interior(b, q);
                let [l, r] = self.child[n as usize];
                stack.push((r, q + 1, depth + 1));
                stack.push((l, q, depth + 1));
            }
        }
        self.stack = stack;
        if !ok {
            nodes.clear();
            runs.clear();
        }
        ok
    }
}

/// Appends the slots `first .. first + count` to `runs`, extending the last run when they
/// continue it.
fn push_run(runs: &mut Vec<[u32; 2]>, first: u32, count: u32) {
    match runs.last_mut() {
        Some(last) if last[0] + last[1] == first => last[1] += count,
        _ => runs.push([first, count]),
    }
}

/// Scratch of the topology-changing operations on a [`MeshBvh`], kept between frames so that
/// they allocate nothing once grown to the largest mesh.
#[derive(Clone, Debug, Default)]
pub struct RestructureWorkspace {
    pub(crate) topo: Topology,
    pub(crate) nodes: Vec<Node>,
    pub(crate) runs: Vec<[u32; 2]>,
    pub(crate) old_prims: Vec<u32>,
    pub(crate) old_tris: Vec<[Vec3; 3]>,
    pub(crate) old_leaf_indices: Vec<[u32; 3]>,
}

impl RestructureWorkspace {
    /// Reserves what a tree over `tris` primitives can need whatever its shape: a binary tree
    /// has fewer than `2 tris` nodes.
    pub fn reserve(&mut self, tris: usize) {
        fn to<T>(v: &mut Vec<T>, cap: usize) {
            if v.capacity() < cap {
                v.reserve_exact(cap - v.len());
            }
        }
        let nodes = 2 * tris.max(1);
        let t = &mut self.topo;
        to(&mut t.bounds, nodes);
        to(&mut t.child, nodes);
        to(&mut t.parent, nodes);
        to(&mut t.touched, nodes);
        to(&mut t.height, nodes);
        to(&mut t.areas, nodes);
        to(&mut t.stack, 2 * MAX_DEPTH + 2);
        to(&mut self.nodes, nodes);
        to(&mut self.runs, tris);
        to(&mut self.old_prims, tris);
        to(&mut self.old_tris, tris);
        to(&mut self.old_leaf_indices, tris);
    }

    /// Bytes held.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        use crate::bvh::held;
        let t = &self.topo;
        held(&t.bounds)
            + held(&t.child)
            + held(&t.parent)
            + held(&t.stack)
            + held(&t.touched)
            + held(&t.height)
            + held(&t.areas)
            + held(&self.nodes)
            + held(&self.runs)
            + held(&self.old_prims)
            + held(&self.old_tris)
            + held(&self.old_leaf_indices)
    }
}

impl MeshBvh {
    /// Replaces the tree by `ws.topo` written back (see the module docs), moving the
    /// leaf-ordered triangles with their slots. Returns false, leaving the tree as it was, when
    /// the topology is deeper than [`MAX_DEPTH`].
    pub(crate) fn apply_topology(&mut self, ws: &mut RestructureWorkspace) -> bool {
        if !ws.topo.write(&self.bvh, &mut ws.nodes, &mut ws.runs) {
            return false;
        }
        gather(&mut ws.old_prims, &self.bvh.prim_indices, &ws.runs);
        gather(&mut ws.old_tris, &self.tris, &ws.runs);
        gather(&mut ws.old_leaf_indices, &self.leaf_indices, &ws.runs);
        debug_assert_eq!(ws.old_tris.len(), self.tris.len());
        take_or_copy(&mut self.bvh.nodes, &mut ws.nodes);
        take_or_copy(&mut self.bvh.prim_indices, &mut ws.old_prims);
        take_or_copy(&mut self.tris, &mut ws.old_tris);
        take_or_copy(&mut self.leaf_indices, &mut ws.old_leaf_indices);
        true
    }
}

/// Puts the scratch's contents into `dst`: by trading the two buffers where `dst`'s is at least
/// as large (so the scratch, shared by meshes of every size, never loses room it has, and
/// `dst` gets one that holds the contents), else by copying. Allocates nothing.
pub(crate) fn take_or_copy<T: Copy>(dst: &mut Vec<T>, scratch: &mut Vec<T>) {
    if dst.capacity() >= scratch.capacity() {
        std::mem::swap(dst, scratch);
    } else {
        dst.clear();
        dst.extend_from_slice(scratch);
    }
}

/// The runs `[first, count]` of `from`, one after another.
fn gather<T: Copy>(out: &mut Vec<T>, from: &[T], runs: &[[u32; 2]]) {
    out.clear();
    for &[first, count] in runs {
        out.extend_from_slice(&from[first as usize..(first + count) as usize]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::anim::generate::{Kind, generate};
    use crate::bvh::BuildParams;
    use crate::bvh::optimize::{OptimizeBudget, OptimizeScratch};

    /// The new slots' old slots, one by one.
    fn slots(runs: &[[u32; 2]]) -> Vec<u32> {
        runs.iter().flat_map(|&[f, c]| f..f + c).collect()
    }

    #[test]
    fn untouched_subtrees_copied_as_blocks_give_the_node_by_node_layout() {
        for kind in [Kind::Swap, Kind::Explode] {
            let g = generate(kind, 6000, 1);
            let (a, b) = (&g.checks[0].1, &g.checks[1].1);
            let pos: Vec<Vec3> = a.iter().zip(b).map(|(a, b)| *a + 0.4 * (*b - *a)).collect();
            let tris: Vec<[u32; 3]> = (0..a.len() as u32 / 3)
                .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
                .collect();
            let mut t = MeshBvh::build_indexed(a, &tris, &BuildParams::BINNED);
            t.refit_indexed(&pos, &tris);
            for share in [0.01, 0.1, 0.5] {
                let mut topo = Topology::default();
                topo.load(t.bvh());
                let budget = OptimizeBudget {
                    share,
                    ..OptimizeBudget::default()
                };
                let stats = topo.optimize(budget, &mut OptimizeScratch::default());
                assert!(stats.moved > 0, "{kind:?} {share}: nothing moved");
                // The write meets untouched subtrees: interior nodes below a touched parent.
                let blocks = (0..topo.len() as u32)
                    .filter(|&n| {
                        let p = topo.parent[n as usize];
                        !topo.is_leaf(n)
                            && !topo.touched[n as usize]
                            && p != NONE
                            && topo.touched[p as usize]
                    })
                    .count();
                assert!(blocks > 0, "{kind:?} {share}: no subtree copied as a block");
                let mut every = topo.clone();
                every.touched.fill(true);
                let (mut n1, mut r1, mut n2, mut r2) = (vec![], vec![], vec![], vec![]);
                assert!(topo.write(t.bvh(), &mut n1, &mut r1));
                assert!(every.write(t.bvh(), &mut n2, &mut r2));
                assert_eq!(n1, n2, "{kind:?} {share}: nodes");
                assert_eq!(slots(&r1), slots(&r2), "{kind:?} {share}: slots");
            }
        }
    }
}
