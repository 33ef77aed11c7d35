//! The binary BVH: plain data (nodes + primitive indices) and the operations on it, one per file.
//!
//! Invariants, checked by [`Bvh::validate`] and kept by every operation:
//! - node 0 is the root; an interior node's children are adjacent and stored after it;
//! - every subtree occupies a contiguous range of nodes and of primitive slots;
//! - `prim_indices` is a permutation of `0 .. n`, each slot owned by exactly one leaf;
//! - every child's box lies inside its parent's; leaves hold `1 ..= max_leaf_size` primitives;
//! - the depth is at most [`MAX_DEPTH`], so traversal runs on a fixed-size stack.
//!
//! A refit never changes the topology; a rebuild, an optimisation or a partial rebuild may.

mod all_hits;
pub mod build;
mod closest_point;
mod cost;
mod mesh;
mod node;
pub mod optimize;
mod overlap;
mod packet;
pub mod partial;
pub mod ray_order;
pub(crate) use packet::with_packet;
mod refit;
pub mod topology;
mod traverse;
mod validate;
pub mod wide;

pub use all_hits::brute_force_all_hits;
pub(crate) use all_hits::keep_nearest;
pub use build::{BuildParams, BuildWorkspace, MAX_BINS, Method};
pub(crate) use closest_point::squared_bound;
pub use closest_point::{PointHit, brute_force_closest_point};
pub use cost::{INTERSECTION_COST, SahCost, TRAVERSAL_COST};
pub use mesh::{MeshBvh, brute_force_any, brute_force_closest};
pub use node::Node;
pub(crate) use overlap::boxes_touch;

/// Bytes a vector's storage holds (its capacity, not its length): what the `storage_bytes` and
/// scratch `memory_bytes` methods count.
pub(crate) fn held<T>(v: &Vec<T>) -> usize {
    v.capacity() * std::mem::size_of::<T>()
}
pub use overlap::{brute_force_overlap_box, brute_force_overlap_sphere};
pub use packet::{
    COHERENT_COS, MAX_PACKET, MIN_PACKET, Mask as PacketMask, PacketMode, RayPacket, TILE_H,
    TILE_W, image_tiles, is_coherent,
};
pub use traverse::{Counters, TraversalStats};
pub use wide::{Child, CollapseMethod, MeshBvh4, MeshBvh8, WideBvh, WideCost, WideNode};

/// The deepest a tree may be (root at depth 0); traversal stacks have this many entries.
pub const MAX_DEPTH: usize = 128;

/// A binary BVH over primitives known by index.
#[derive(Debug, Default, PartialEq)]
pub struct Bvh {
    nodes: Vec<Node>,
    prim_indices: Vec<u32>,
    max_leaf_size: u32,
}

/// `clone_from` reuses the target's buffers (allocating only to grow).
impl Clone for Bvh {
    fn clone(&self) -> Self {
        Self {
            nodes: self.nodes.clone(),
            prim_indices: self.prim_indices.clone(),
            max_leaf_size: self.max_leaf_size,
        }
    }

    fn clone_from(&mut self, source: &Self) {
        self.nodes.clone_from(&source.nodes);
        self.prim_indices.clone_from(&source.prim_indices);
        self.max_leaf_size = source.max_leaf_size;
    }
}

impl Bvh {
    /// The tree over no primitive: no node at all.
    #[must_use]
    pub fn empty(max_leaf_size: u32) -> Self {
        Self {
            nodes: Vec::new(),
            prim_indices: Vec::new(),
            max_leaf_size,
        }
    }

    /// The nodes; node 0 is the root.
    #[must_use]
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// The primitive in each slot; leaves own contiguous ranges of slots.
    #[must_use]
    pub fn prim_indices(&self) -> &[u32] {
        &self.prim_indices
    }

    /// Number of primitives.
    #[must_use]
    pub fn prim_count(&self) -> usize {
        self.prim_indices.len()
    }

    /// Largest leaf size the tree was built with.
    #[must_use]
    pub fn max_leaf_size(&self) -> u32 {
        self.max_leaf_size
    }

    /// Bytes held by nodes and primitive indices.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<Node>() + self.prim_indices.len() * 4
    }

    /// Bytes the node and index storage holds, reserved room included.
    #[must_use]
    pub fn storage_bytes(&self) -> usize {
        use crate::bvh::held;
        held(&self.nodes) + held(&self.prim_indices)
    }

    /// Box of the whole tree (empty for the empty tree).
    #[must_use]
    pub fn bounds(&self) -> crate::geom::Aabb {
        self.nodes
            .first()
            .map_or(crate::geom::Aabb::EMPTY, Node::bounds)
    }

    /// The primitive slots of the subtree at node `n`: (first, count). Its first slot is its
    /// leftmost leaf's; its last, its rightmost leaf's end.
    #[must_use]
    pub(crate) fn slot_range(&self, n: u32) -> (u32, u32) {
        let nodes = &self.nodes;
        let (mut lo, mut hi) = (n, n);
        while !nodes[lo as usize].is_leaf() {
            lo = nodes[lo as usize].first;
        }
        while !nodes[hi as usize].is_leaf() {
            hi = nodes[hi as usize].first + 1;
        }
        let first = nodes[lo as usize].first;
        let last = &nodes[hi as usize];
        (first, last.first + last.count - first)
    }

    /// Depth of the deepest leaf (the root is at depth 0; 0 for the empty tree).
    #[must_use]
    pub fn depth(&self) -> usize {
        let mut depth = vec![0u16; self.nodes.len()];
        let mut deepest = 0;
        for (i, n) in self.nodes.iter().enumerate() {
            if !n.is_leaf() {
                let d = depth[i] + 1;
                depth[n.first as usize] = d;
                depth[n.first as usize + 1] = d;
                deepest = deepest.max(d as usize);
            }
        }
        deepest
    }
}
