//! A tree's topology in linked form (children and parent per node), for the optimisation
//! ([`super::optimize`]), which moves single nodes; written back in the builders' layout, so
//! that refit and traversal work on the result unchanged. (The partial rebuild, which moves
//! whole subtrees, writes its tree directly; it shares [`RestructureWorkspace`]'s buffers.)
//!
//! Write-back lays the reachable nodes out depth first: a node's two children are allocated
//! together, then the left child's descendants, then the right's, so every node's children are
//! adjacent and after it and every subtree owns one range of nodes and one of primitive slots.
//! Leaves keep their primitives; the new slot order is returned as a permutation of the old.

use super::{Bvh, MAX_DEPTH, MeshBvh, Node};
use crate::geom::Aabb;
use glam::Vec3;

/// Marks "no node" (a leaf's children, the root's parent).
pub(crate) const NONE: u32 = u32::MAX;

/// A tree in linked form: node `i` has box `bounds[i]`; interior nodes have `child[i]`, leaves
/// `child[i] == [NONE; 2]` and primitive slots `leaf[i]` (first, count) of the tree it was
/// loaded from. Nodes not reachable from `root` are unused.
#[derive(Clone, Debug, Default)]
pub struct Topology {
    pub(crate) bounds: Vec<Aabb>,
    pub(crate) child: Vec<[u32; 2]>,
    pub(crate) parent: Vec<u32>,
    pub(crate) leaf: Vec<[u32; 2]>,
    pub(crate) root: u32,
    /// Write-back stack: (node, position, depth).
    stack: Vec<(u32, u32, u32)>,
    /// Each node's position in the last write-back ([`NONE`] when not reachable).
    pos: Vec<u32>,
}

impl Topology {
    /// Loads `bvh`'s topology (node ids are its node indices). Allocates only to grow.
    pub fn load(&mut self, bvh: &Bvh) {
        let nodes = bvh.nodes();
        self.bounds.clear();
        self.child.clear();
        self.leaf.clear();
        self.parent.clear();
        self.parent.resize(nodes.len(), NONE);
        for (i, n) in nodes.iter().enumerate() {
            self.bounds.push(n.bounds());
            if n.is_leaf() {
                self.child.push([NONE; 2]);
                self.leaf.push([n.first, n.count]);
            } else {
                self.child.push([n.first, n.first + 1]);
                self.leaf.push([0, 0]);
                self.parent[n.first as usize] = i as u32;
                self.parent[n.first as usize + 1] = i as u32;
            }
        }
        self.root = 0;
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
            n = self.parent[n as usize];
        }
    }

    /// Where node `n` went in the last write-back.
    #[must_use]
    pub fn position(&self, n: u32) -> u32 {
        self.pos[n as usize]
    }

    /// Writes the reachable tree into `nodes` in the builders' layout, and into `perm` the old
    /// primitive slot of each new slot. Returns false (writing nothing) when the tree is deeper
    /// than [`MAX_DEPTH`]. Allocates only to grow.
    pub(crate) fn write(&mut self, nodes: &mut Vec<Node>, perm: &mut Vec<u32>) -> bool {
        nodes.clear();
        perm.clear();
        if self.bounds.is_empty() {
            return true;
        }
        let mut stack = std::mem::take(&mut self.stack);
        stack.clear();
        stack.push((self.root, 0, 0));
        nodes.push(Node::default());
        self.pos.clear();
        self.pos.resize(self.bounds.len(), NONE);
        let mut ok = true;
        while let Some((n, pos, depth)) = stack.pop() {
            if depth as usize > MAX_DEPTH {
                ok = false;
                break;
            }
            let b = self.bounds[n as usize];
            self.pos[n as usize] = pos;
            if self.is_leaf(n) {
                let [first, count] = self.leaf[n as usize];
                nodes[pos as usize] = Node::leaf(b, perm.len() as u32, count);
                perm.extend(first..first + count);
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
            perm.clear();
        }
        ok
    }
}

/// Scratch of the topology-changing operations on a [`MeshBvh`], kept between frames so that
/// they allocate nothing once grown to the largest mesh.
#[derive(Clone, Debug, Default)]
pub struct RestructureWorkspace {
    pub(crate) topo: Topology,
    pub(crate) nodes: Vec<Node>,
    pub(crate) perm: Vec<u32>,
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
        to(&mut t.leaf, nodes);
        to(&mut t.pos, nodes);
        to(&mut t.stack, 2 * MAX_DEPTH + 2);
        to(&mut self.nodes, nodes);
        to(&mut self.perm, tris);
        to(&mut self.old_prims, tris);
        to(&mut self.old_tris, tris);
        to(&mut self.old_leaf_indices, tris);
    }

    /// Bytes held.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        let t = &self.topo;
        t.bounds.capacity() * std::mem::size_of::<Aabb>()
            + (t.child.capacity() + t.leaf.capacity()) * 8
            + t.parent.capacity() * 4
            + self.nodes.capacity() * std::mem::size_of::<Node>()
            + (self.perm.capacity() + self.old_prims.capacity()) * 4
            + self.old_tris.capacity() * 36
            + self.old_leaf_indices.capacity() * 12
    }
}

impl MeshBvh {
    /// Replaces the tree by `ws.topo` written back (see the module docs), moving the
    /// leaf-ordered triangles with their slots. Returns false, leaving the tree as it was, when
    /// the topology is deeper than [`MAX_DEPTH`].
    pub(crate) fn apply_topology(&mut self, ws: &mut RestructureWorkspace) -> bool {
        if !ws.topo.write(&mut ws.nodes, &mut ws.perm) {
            return false;
        }
        debug_assert_eq!(ws.perm.len(), self.tris.len());
        gather(&mut ws.old_prims, &self.bvh.prim_indices, &ws.perm);
        gather(&mut ws.old_tris, &self.tris, &ws.perm);
        gather(&mut ws.old_leaf_indices, &self.leaf_indices, &ws.perm);
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

/// `out[i] = from[perm[i]]`.
fn gather<T: Copy>(out: &mut Vec<T>, from: &[T], perm: &[u32]) {
    out.clear();
    out.extend(perm.iter().map(|&p| from[p as usize]));
}
