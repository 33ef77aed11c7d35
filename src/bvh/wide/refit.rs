//! Refit of the wide tree in place: one reverse sweep over the nodes (children come after their
//! parent), computing each leaf lane's box straight from its triangles' vertices while copying
//! them into the leaf-ordered array, and each interior lane's box as the union of its node's
//! lanes. Large trees are refitted as parallel subtrees (every subtree is a contiguous range of
//! nodes and of triangle slots).

use super::lanes::bound_lanes;
use super::{Child, TriBlock, UNUSED, WideBvh, WideNode};
use crate::geom::{Aabb, TriMesh};
use glam::Vec3;
use rayon::prelude::*;

/// Subtrees with at least this many nodes are refitted as parallel tasks.
const PARALLEL_NODES: usize = 1 << 11;
/// How many blocks ahead refit prefetches vertex positions.
const PREFETCH_BLOCKS: usize = 8;
/// Blocks gathered per parallel task.
const GATHER_CHUNK: usize = 1 << 12;

impl<const K: usize> WideBvh<K> {
    /// Refits for new vertex positions of the same topology. No allocation.
    ///
    /// # Panics
    /// When `mesh` has another triangle count than the tree, or a vertex index is out of range.
    pub fn refit(&mut self, mesh: &TriMesh) {
        self.refit_indexed(&mesh.positions, &mesh.indices);
    }

    /// [`WideBvh::refit`] from positions and triangle indices held elsewhere (only their count
    /// is read: the tree keeps its own copy of each triangle's vertex indices). No allocation.
    ///
    /// # Panics
    /// When the triangle count differs from the built one, or a vertex index is out of range.
    pub fn refit_indexed(&mut self, positions: &[Vec3], indices: &[[u32; 3]]) {
        assert_eq!(
            indices.len(),
            self.prim_count,
            "refit needs the same triangles"
        );
        if rayon::current_num_threads() > 1 && self.nodes.len() >= PARALLEL_NODES {
            gather(&mut self.blocks, &self.block_indices, positions);
            refit_par(
                &mut self.nodes,
                0,
                Boxes {
                    blocks: &self.blocks,
                },
            );
        } else {
            let mut leaf = Gather {
                positions,
                indices: &self.block_indices,
                blocks: &mut self.blocks,
                prefetched: 0,
            };
            refit_two_pass(&mut self.nodes, &mut leaf);
        }
    }

    /// Recomputes every box from the triangle blocks as they are.
    pub(super) fn refit_boxes(&mut self) {
        refit_par(
            &mut self.nodes,
            0,
            Boxes {
                blocks: &self.blocks,
            },
        );
    }
}

/// How a leaf lane's box is found.
trait LeafBox {
    /// The box of the triangles in blocks `first .. first + count`.
    fn leaf(&mut self, first: u32, count: u32) -> Aabb;
}

/// Reads the triangle blocks.
#[derive(Clone, Copy)]
struct Boxes<'a> {
    blocks: &'a [TriBlock],
}

impl LeafBox for Boxes<'_> {
    #[inline]
    fn leaf(&mut self, first: u32, count: u32) -> Aabb {
        bound(&self.blocks[first as usize..(first + count) as usize])
    }
}

/// Gathers the moved vertices into the triangle blocks and bounds them in the same pass.
struct Gather<'a> {
    positions: &'a [Vec3],
    indices: &'a [[[u32; 3]; 4]],
    blocks: &'a mut [TriBlock],
    /// Blocks below this one have had their vertices prefetched.
    prefetched: usize,
}

impl LeafBox for Gather<'_> {
    #[inline]
    fn leaf(&mut self, first: u32, count: u32) -> Aabb {
        let (s, e) = (first as usize, (first + count) as usize);
        // Leaves come in block order: ask for the vertices of the next few blocks now, so
        // that their (scattered) loads overlap with this leaf's work.
        let ahead = (e + PREFETCH_BLOCKS).min(self.indices.len());
        for idx in &self.indices[self.prefetched.max(e).min(ahead)..ahead] {
            for v in idx {
                if v[0] != UNUSED {
                    crate::simd::prefetch(&self.positions[v[0] as usize]);
                    crate::simd::prefetch(&self.positions[v[2] as usize]);
                }
            }
        }
        self.prefetched = ahead;
        let local = &mut self.blocks[s..e];
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

/// Writes the vertices of every used lane into `blocks`.
#[inline(always)]
fn fill(blocks: &mut [TriBlock], indices: &[[[u32; 3]; 4]], pos: &[Vec3]) {
    for (b, idx) in blocks.iter_mut().zip(indices) {
        for (l, idx) in idx.iter().enumerate() {
            if idx[0] != UNUSED {
                b.set(l, &idx.map(|v| pos[v as usize]));
            }
        }
    }
}

/// The box of the triangles in some blocks: a NaN coordinate (unused lanes are all NaN) is
/// skipped; when an infinite or all-NaN axis remains, the binary tree's sanitized boxes.
#[inline(always)]
fn bound(blocks: &[TriBlock]) -> Aabb {
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

/// Copies each used lane's triangle into its block, in parallel chunks.
fn gather(blocks: &mut [TriBlock], indices: &[[[u32; 3]; 4]], pos: &[Vec3]) {
    blocks
        .par_chunks_mut(GATHER_CHUNK)
        .zip(indices.par_chunks(GATHER_CHUNK))
        .for_each(|(b, i)| fill(b, i, pos));
}

/// Refits the subtree whose root is `nodes[0]` (global index `base`) and which owns exactly the
/// nodes in `nodes`, splitting the root's large child subtrees off as parallel tasks.
fn refit_par<const K: usize>(nodes: &mut [WideNode<K>], base: u32, leaf: Boxes<'_>) {
    if nodes.len() < PARALLEL_NODES {
        refit_sweep(nodes, base, &mut { leaf });
        return;
    }
    let end_all = base + nodes.len() as u32;
    let (root, mut rest) = nodes.split_first_mut().expect("a subtree has a root");
    // The interior children's subtrees follow the root in lane order, each contiguous.
    let mut tasks: Vec<(usize, &mut [WideNode<K>], u32)> = Vec::with_capacity(K);
    let mut next = base + 1;
    for k in 0..K {
        if let Child::Node(c) = root.child(k) {
            debug_assert_eq!(c, next);
            let end = (k + 1..K)
                .find_map(|j| match root.child(j) {
                    Child::Node(d) => Some(d),
                    _ => None,
                })
                .unwrap_or(end_all);
            let (mine, after) = std::mem::take(&mut rest).split_at_mut((end - c) as usize);
            tasks.push((k, mine, c));
            rest = after;
            next = end;
        }
    }
    let boxes: Vec<(usize, Aabb)> = tasks
        .into_par_iter()
        .map(|(k, sub, b)| {
            refit_par(sub, b, leaf);
            (k, sub[0].bounds())
        })
        .collect();
    for (k, b) in boxes {
        root.set_lane(k, b);
    }
    let mut leaf = leaf;
    for k in 0..K {
        if let Child::Leaf { first, count } = root.child(k) {
            root.set_lane(k, leaf.leaf(first, count));
        }
    }
}

/// One reverse sweep over a contiguous closed subtree (global index of `nodes[0]` is `base`):
/// every child node is met before its parent.
fn refit_sweep<const K: usize>(nodes: &mut [WideNode<K>], base: u32, leaf: &mut impl LeafBox) {
    for i in (0..nodes.len()).rev() {
        let (head, tail) = nodes.split_at_mut(i + 1);
        let node = &mut head[i];
        for k in 0..K {
            let b = match node.child(k) {
                Child::Empty => continue,
                Child::Leaf { first, count } => leaf.leaf(first, count),
                Child::Node(c) => tail[(c - base) as usize - i - 1].bounds(),
            };
            node.set_lane(k, b);
        }
    }
}

/// The refit of the whole tree on one thread: first every leaf lane in node order (which is
/// block order, so blocks and their vertex indices stream forward), then every interior lane in
/// one reverse sweep.
fn refit_two_pass<const K: usize>(nodes: &mut [WideNode<K>], leaf: &mut impl LeafBox) {
    for node in nodes.iter_mut() {
        for k in 0..K {
            if let Child::Leaf { first, count } = node.child(k) {
                node.set_lane(k, leaf.leaf(first, count));
            }
        }
    }
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
