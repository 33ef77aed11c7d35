//! Refit of the wide tree in place: one reverse sweep over the nodes (children come after their
//! parent), computing each leaf lane's box straight from its triangles' vertices while copying
//! them into the leaf-ordered array, and each interior lane's box as the union of its node's
//! lanes. Large trees are refitted as parallel subtrees (every subtree is a contiguous range of
//! nodes and of triangle slots).

use super::lanes::bound_lanes;
use super::{Child, NO_PRIM, TriBlock, WideBvh, WideNode};
use crate::geom::{Aabb, TriMesh};
use glam::Vec3;
use rayon::prelude::*;

/// Subtrees with at least this many nodes are refitted as parallel tasks.
const PARALLEL_NODES: usize = 1 << 11;
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
            gather(
                &mut self.blocks,
                &self.block_indices,
                &self.block_prims,
                positions,
            );
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
                prims: &self.block_prims,
                blocks: &mut self.blocks,
            };
            refit_sweep(&mut self.nodes, 0, &mut leaf);
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
    prims: &'a [[u32; 4]],
    blocks: &'a mut [TriBlock],
}

impl LeafBox for Gather<'_> {
    #[inline]
    fn leaf(&mut self, first: u32, count: u32) -> Aabb {
        let (s, e) = (first as usize, (first + count) as usize);
        let local = &mut self.blocks[s..e];
        fill(
            local,
            &self.indices[s..e],
            &self.prims[s..e],
            self.positions,
        );
        bound(local)
    }
}

/// Writes the vertices of every used lane into `blocks`.
#[inline(always)]
fn fill(blocks: &mut [TriBlock], indices: &[[[u32; 3]; 4]], prims: &[[u32; 4]], pos: &[Vec3]) {
    for ((b, idx), p) in blocks.iter_mut().zip(indices).zip(prims) {
        for l in 0..4 {
            if p[l] != NO_PRIM {
                b.set(l, &idx[l].map(|v| pos[v as usize]));
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
fn gather(blocks: &mut [TriBlock], indices: &[[[u32; 3]; 4]], prims: &[[u32; 4]], pos: &[Vec3]) {
    blocks
        .par_chunks_mut(GATHER_CHUNK)
        .zip(indices.par_chunks(GATHER_CHUNK))
        .zip(prims.par_chunks(GATHER_CHUNK))
        .for_each(|((b, i), p)| fill(b, i, p, pos));
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
