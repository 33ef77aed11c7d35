//! Refit of the wide tree in place, in two passes: first every leaf lane, in node order (which
//! is block order, so the triangle blocks and their vertex indices stream forward), copying the
//! moved vertices into the blocks and bounding them in the same pass, with the scattered vertex
//! loads prefetched a few blocks ahead; then every interior lane as the union of its node's
//! lanes, in one reverse sweep (children come after their parent). On several threads the leaf
//! pass runs on chunks of nodes in parallel (each chunk owns a contiguous run of blocks), split
//! with `rayon::join`.

use super::lanes::bound_lanes;
use super::{Child, TriBlock, UNUSED, WideBvh, WideNode};
use crate::geom::{Aabb, TriMesh};
use glam::Vec3;

/// Trees with at least this many nodes refit their leaves in parallel.
const PARALLEL_NODES: usize = 1 << 11;
/// How many blocks ahead refit prefetches vertex positions.
const PREFETCH_BLOCKS: usize = 8;

impl<const K: usize> WideBvh<K> {
    /// Refits for new vertex positions of the same topology. Allocates nothing itself (on
    /// several threads, `rayon::join` from outside a pool queues jobs as rayon does).
    ///
    /// # Panics
    /// When `mesh` has another triangle count than the tree, or a vertex index is out of range.
    pub fn refit(&mut self, mesh: &TriMesh) {
        self.refit_indexed(&mesh.positions, &mesh.indices);
    }

    /// [`WideBvh::refit`] from positions and triangle indices held elsewhere (only their count
    /// is read: the tree keeps its own copy of each triangle's vertex indices).
    ///
    /// # Panics
    /// When the triangle count differs from the built one, or a vertex index is out of range.
    pub fn refit_indexed(&mut self, positions: &[Vec3], indices: &[[u32; 3]]) {
        assert_eq!(
            indices.len(),
            self.prim_count,
            "refit needs the same triangles"
        );
        let threads = rayon::current_num_threads();
        if threads > 1 && self.nodes.len() >= PARALLEL_NODES {
            let chunk = self.nodes.len().div_ceil(4 * threads);
            par_leaf_pass(
                &mut self.nodes,
                &mut self.blocks,
                0,
                positions,
                &self.block_indices,
                chunk,
            );
        } else {
            let mut g = Gather {
                positions,
                indices: &self.block_indices,
                blocks: &mut self.blocks,
                base: 0,
                prefetched: 0,
            };
            leaf_pass(&mut self.nodes, &mut g);
        }
        interior_pass(&mut self.nodes);
        self.update_coord_max();
    }
}

/// How a leaf lane's box is found.
trait LeafBox {
    /// The box of the triangles in blocks `first .. first + count`.
    fn leaf(&mut self, first: u32, count: u32) -> Aabb;
}

/// Gathers the moved vertices into the triangle blocks and bounds them in the same pass.
struct Gather<'a> {
    positions: &'a [Vec3],
    /// Every block's vertex indices.
    indices: &'a [[[u32; 3]; 4]],
    /// The blocks from `base` on.
    blocks: &'a mut [TriBlock],
    base: usize,
    /// Blocks below this one have had their vertices prefetched.
    prefetched: usize,
}

impl LeafBox for Gather<'_> {
    #[inline]
    fn leaf(&mut self, first: u32, count: u32) -> Aabb {
        let (s, e) = (first as usize, (first + count) as usize);
        // Leaves come in block order: ask for the vertices of the next few blocks now, so
        // that their scattered loads overlap with this leaf's work.
        let ahead = (e + PREFETCH_BLOCKS).min(self.base + self.blocks.len());
        for idx in &self.indices[self.prefetched.max(e).min(ahead)..ahead] {
            for v in idx {
                if v[0] != UNUSED {
                    crate::simd::prefetch(&self.positions[v[0] as usize]);
                    crate::simd::prefetch(&self.positions[v[2] as usize]);
                }
            }
        }
        self.prefetched = ahead;
        let local = &mut self.blocks[s - self.base..e - self.base];
        // Bound the vertices as they are loaded (reading the block back right after writing
        // single lanes would stall on store forwarding).
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for (b, idx) in local.iter_mut().zip(&self.indices[s..e]) {
            for (l, idx) in idx.iter().enumerate() {
                if idx[0] == UNUSED {
                    continue;
                }
                let t = idx.map(|v| self.positions[v as usize]);
                for p in &t {
                    for a in 0..3 {
                        // Never keeps a NaN coordinate.
                        lo[a] = if p[a] < lo[a] { p[a] } else { lo[a] };
                        hi[a] = if p[a] > hi[a] { p[a] } else { hi[a] };
                    }
                }
                b.set(l, &t);
            }
        }
        let b = Aabb::new(Vec3::from(lo), Vec3::from(hi));
        if b.is_finite() { b } else { bound(local) }
    }
}

/// The box of the triangles in some blocks: a NaN coordinate (unused lanes are all NaN) is
/// skipped; when an infinite or all-NaN axis remains, the binary tree's sanitized boxes.
#[inline(always)]
pub(super) fn bound(blocks: &[TriBlock]) -> Aabb {
    let b = bound_lanes(blocks);
    if b.is_finite() {
        b
    } else {
        blocks
            .iter()
            .flat_map(|b| (0..4).map(|l| b.get(l)))
            .filter(|t| !t.iter().all(|v| v.is_nan()))
            .fold(Aabb::EMPTY, |b, t| b.union(Aabb::of_triangle(&t)))
    }
}

/// Sets every leaf lane's box, in node order.
/// The leaf pass over `nodes` (whose leaves own `blocks`, the blocks from `base` on) in
/// parallel, split in halves with `rayon::join` down to `chunk` nodes: each half's nodes own a
/// contiguous run of blocks (blocks are given out in node order), found by scanning the first
/// half's leaves. Allocates nothing.
fn par_leaf_pass<const K: usize>(
    nodes: &mut [WideNode<K>],
    blocks: &mut [TriBlock],
    base: usize,
    positions: &[Vec3],
    indices: &[[[u32; 3]; 4]],
    chunk: usize,
) {
    if nodes.len() <= chunk {
        let mut g = Gather {
            positions,
            indices,
            blocks,
            base,
            prefetched: 0,
        };
        leaf_pass(nodes, &mut g);
        return;
    }
    let mid = (nodes.len() / chunk / 2).max(1) * chunk;
    let (a, b) = nodes.split_at_mut(mid);
    let end = a
        .iter()
        .flat_map(|n| (0..K).map(move |k| n.child(k)))
        .filter_map(|c| match c {
            Child::Leaf { first, count } => Some((first + count) as usize),
            _ => None,
        })
        .max()
        .unwrap_or(base);
    let (ba, bb) = blocks.split_at_mut(end - base);
    rayon::join(
        || par_leaf_pass(a, ba, base, positions, indices, chunk),
        || par_leaf_pass(b, bb, end, positions, indices, chunk),
    );
}

fn leaf_pass<const K: usize>(nodes: &mut [WideNode<K>], leaf: &mut impl LeafBox) {
    for node in nodes.iter_mut() {
        for k in 0..K {
            if let Child::Leaf { first, count } = node.child(k) {
                node.set_lane(k, leaf.leaf(first, count));
            }
        }
    }
}

/// Sets every interior lane's box to the union of its node's lanes, in one reverse sweep.
pub(super) fn interior_pass<const K: usize>(nodes: &mut [WideNode<K>]) {
    for i in (0..nodes.len()).rev() {
        let (head, tail) = nodes.split_at_mut(i + 1);
        let node = &mut head[i];
        for k in 0..K {
            if let Child::Node(c) = node.child(k) {
                node.set_lane(k, tail[c as usize - i - 1].bounds());
            }
        }
    }
}
