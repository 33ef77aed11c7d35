//! The collapse's last step: every leaf lane's triangle slots packed into blocks of four (with
//! their triangle and vertex indices) and bounded, the lane re-pointed at its blocks. Blocks
//! are given out in node order, lanes in order, so each run of nodes owns a run of blocks: on
//! several threads, runs of nodes are filled in parallel (split with `rayon::join`), with the
//! same result as one pass.

use super::refit::bound;
use super::{Child, TriBlock, TriSlots, UNUSED, WideNode, encode_leaf};
use glam::Vec3;

/// Trees with at least this many nodes fill their blocks in parallel.
const PARALLEL_NODES: usize = 1 << 11;

/// Blocks the leaf lanes of `nodes` need (their lanes still give triangle slots).
pub(super) fn blocks_needed<const K: usize>(nodes: &[WideNode<K>]) -> usize {
    nodes
        .iter()
        .flat_map(|n| (0..K).map(move |k| n.child(k)))
        .map(|c| match c {
            Child::Leaf { count, .. } => count.div_ceil(4) as usize,
            _ => 0,
        })
        .sum()
}

/// Fills `blocks` and `indices` (as many as [`blocks_needed`]) from `m`'s slots for the leaf
/// lanes of `nodes`, sets each leaf lane's box and points it at its blocks.
pub(super) fn fill_leaves<const K: usize>(
    nodes: &mut [WideNode<K>],
    blocks: &mut [TriBlock],
    indices: &mut [[[u32; 3]; 4]],
    m: TriSlots<'_>,
) {
    let threads = rayon::current_num_threads();
    let chunk = if threads > 1 && nodes.len() >= PARALLEL_NODES {
        nodes.len().div_ceil(4 * threads)
    } else {
        nodes.len().max(1)
    };
    fill_part(nodes, blocks, indices, 0, m, chunk);
}

/// [`fill_leaves`] over a run of nodes whose blocks start at block `base`.
fn fill_part<const K: usize>(
    nodes: &mut [WideNode<K>],
    blocks: &mut [TriBlock],
    indices: &mut [[[u32; 3]; 4]],
    base: u32,
    m: TriSlots<'_>,
    chunk: usize,
) {
    if nodes.len() <= chunk {
        fill_run(nodes, blocks, indices, base, m);
        return;
    }
    let mid = (nodes.len() / chunk / 2).max(1) * chunk;
    let (a, b) = nodes.split_at_mut(mid);
    let k = blocks_needed(a);
    let (ba, bb) = blocks.split_at_mut(k);
    let (ia, ib) = indices.split_at_mut(k);
    rayon::join(
        || fill_part(a, ba, ia, base, m, chunk),
        || fill_part(b, bb, ib, base + k as u32, m, chunk),
    );
}

/// One thread's run of nodes.
fn fill_run<const K: usize>(
    nodes: &mut [WideNode<K>],
    blocks: &mut [TriBlock],
    indices: &mut [[[u32; 3]; 4]],
    base: u32,
    m: TriSlots<'_>,
) {
    match m {
        // The copies are read in order and need no hint.
        TriSlots::Copied {
            tris,
            indices: vi,
            prims,
        } => fill_with(
            nodes,
            blocks,
            indices,
            base,
            |s| (tris[s as usize], vi[s as usize], prims[s as usize]),
            |_, _| {},
        ),
        // Slots are looked up in the mesh at random: the vertex indices of the leaves two
        // nodes ahead and the vertices of the next node's are asked for first.
        TriSlots::Mesh { .. } => {
            let ask = |n: Option<&WideNode<K>>, f: &dyn Fn(u32)| {
                for k in 0..K {
                    if let Some(Child::Leaf { first, count }) = n.map(|n| n.child(k)) {
                        (first..first + count).for_each(f);
                    }
                }
            };
            ask(nodes.first(), &|s| m.prefetch_indices(s));
            ask(nodes.get(1), &|s| m.prefetch_indices(s));
            ask(nodes.first(), &|s| m.prefetch_corners(s));
            fill_with(
                nodes,
                blocks,
                indices,
                base,
                |s| m.slot(s),
                |nodes, i| {
                    ask(nodes.get(i + 2), &|s| m.prefetch_indices(s));
                    ask(nodes.get(i + 1), &|s| m.prefetch_corners(s));
                },
            );
        }
    }
}

/// [`fill_run`] with each slot's corners, vertex indices and triangle index from `slot`, and
/// `ahead(nodes, i)` called before node `i` is filled.
fn fill_with<const K: usize>(
    nodes: &mut [WideNode<K>],
    blocks: &mut [TriBlock],
    indices: &mut [[[u32; 3]; 4]],
    base: u32,
    slot: impl Fn(u32) -> ([Vec3; 3], [u32; 3], u32),
    ahead: impl Fn(&[WideNode<K>], usize),
) {
    let mut next = 0usize;
    for i in 0..nodes.len() {
        ahead(nodes, i);
        let n = &mut nodes[i];
        for k in 0..K {
            let Child::Leaf { first, count } = n.child(k) else {
                continue;
            };
            let start = next;
            for s in (first..first + count).step_by(4) {
                let mut b = TriBlock::EMPTY;
                let mut idx = [[UNUSED; 3]; 4];
                for (l, at) in (s..(first + count).min(s + 4)).enumerate() {
                    let (t, vi, prim) = slot(at);
                    b.set(l, &t);
                    b.prims[l] = prim;
                    idx[l] = vi;
                }
                blocks[next] = b;
                indices[next] = idx;
                next += 1;
            }
            n.child[k] = encode_leaf(base + start as u32, (next - start) as u32);
            n.set_lane(k, bound(&blocks[start..next]));
        }
    }
}
