//! Partial rebuild: rebuild the top of a refitted tree over a cut of its subtrees, and rebuild
//! from scratch only the cut subtrees that degraded most (selective restructuring: Lauterbach
//! et al. 2006, Yoon et al. 2007).
//!
//! Motion that moves parts of a mesh apart (pieces, limbs) spoils the upper levels, whose
//! boxes now span distant parts, while the subtrees inside each part stay good; deformation
//! spoils subtrees where it happens. The cut is the set of largest subtrees of at most
//! `n / CUT_TARGET` triangles, taken at each full build and kept (with each subtree's SAH then,
//! normalised by its own box: a scale-free reference) until the next. A partial rebuild ranks
//! the cut subtrees by their SAH now over that reference, rebuilds the worst ones up to a share
//! of the triangles, then builds the top over the cut subtrees' boxes with the binned SAH.

use super::node::descendants_end;
use super::topology::RestructureWorkspace;
use super::{BuildParams, BuildWorkspace, Bvh, MAX_DEPTH, MeshBvh, Node, SahCost};
use crate::geom::Aabb;
use std::sync::{Mutex, PoisonError};

/// Cut subtrees a mesh is split into (about; fewer for small meshes).
pub const CUT_TARGET: usize = 256;

/// A mesh's cut: the subtrees a partial rebuild keeps or rebuilds, and their reference SAH.
#[derive(Clone, Debug, Default)]
pub struct PartialCut {
    /// Root node of each cut subtree.
    roots: Vec<u32>,
    /// Each one's SAH normalised by its root's area when it was last built.
    reference: Vec<f32>,
    /// Each one's height (0 for a leaf).
    height: Vec<u32>,
}

/// What a partial rebuild did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PartialStats {
    /// Subtrees in the cut.
    pub cut: u32,
    /// Cut subtrees rebuilt from scratch, and their triangles.
    pub rebuilt: u32,
    pub rebuilt_tris: u32,
}

/// Scratch of partial rebuilds, kept between calls.
#[derive(Debug, Default)]
pub struct PartialScratch {
    counts: Vec<u32>,
    heights: Vec<u32>,
    costs: Vec<f32>,
    ranked: Vec<(f32, u32)>,
    stack: Vec<u32>,
    boxes: Vec<Aabb>,
    top: Bvh,
    build: BuildWorkspace,
    /// Each cut subtree's part.
    work: Vec<CutWork>,
    /// The rebuilt subtrees' nodes, the one at slot `f` from `2 f`.
    built: Vec<Node>,
    /// The cut subtrees in the new tree's order.
    order: Vec<u32>,
    /// The layout's stack: (top node, position, depth).
    emit: Vec<(u32, u32, u32)>,
    /// One per thread of the pool (and one for a caller outside it).
    tasks: Vec<Mutex<TaskScratch>>,
}

impl PartialScratch {
    /// Bytes held (the per-thread parts locked one at a time).
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        use crate::bvh::held;
        let tasks: usize = self
            .tasks
            .iter()
            .map(|t| {
                t.lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .memory_bytes()
            })
            .sum();
        held(&self.counts)
            + held(&self.heights)
            + held(&self.costs)
            + held(&self.ranked)
            + held(&self.stack)
            + held(&self.boxes)
            + self.top.storage_bytes()
            + self.build.memory_bytes()
            + held(&self.work)
            + held(&self.built)
            + held(&self.order)
            + held(&self.emit)
            + tasks
    }

    /// A task scratch for each thread of the current pool and one for a caller outside it
    /// (allocates only when the pool has more threads than before).
    fn task_per_thread(&mut self) {
        let threads = rayon::current_num_threads() + 1;
        if self.tasks.len() < threads {
            self.tasks.resize_with(threads, Default::default);
        }
    }
}

impl Clone for PartialScratch {
    fn clone(&self) -> Self {
        let lock =
            |t: &Mutex<TaskScratch>| t.lock().unwrap_or_else(PoisonError::into_inner).clone();
        Self {
            counts: self.counts.clone(),
            heights: self.heights.clone(),
            costs: self.costs.clone(),
            ranked: self.ranked.clone(),
            stack: self.stack.clone(),
            boxes: self.boxes.clone(),
            top: self.top.clone(),
            build: self.build.clone(),
            work: self.work.clone(),
            built: self.built.clone(),
            order: self.order.clone(),
            emit: self.emit.clone(),
            tasks: self.tasks.iter().map(|t| Mutex::new(lock(t))).collect(),
        }
    }
}

impl PartialCut {
    /// Bytes held.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        use crate::bvh::held;
        held(&self.roots) + held(&self.reference) + held(&self.height)
    }

    /// Subtrees in the cut.
    #[must_use]
    pub fn len(&self) -> usize {
        self.roots.len()
    }

    /// True before the first [`PartialCut::reset`].
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.roots.is_empty()
    }

    /// Forgets the cut (after an operation that moved its subtrees): the next partial rebuild
    /// takes a new one.
    pub fn clear(&mut self) {
        self.roots.clear();
        self.reference.clear();
        self.height.clear();
    }

    /// Marks every cut subtree as degraded, so that the next partial rebuild of share 1
    /// rebuilds them all (to size scratch buffers ahead of the frame loop).
    pub fn mark_all_degraded(&mut self) {
        self.reference.fill(f32::MIN_POSITIVE);
    }

    /// Takes the cut of a freshly built tree. Allocates only to grow.
    pub fn reset(&mut self, tree: &MeshBvh, s: &mut PartialScratch) {
        self.clear();
        let bvh = tree.bvh();
        if bvh.nodes().is_empty() {
            return;
        }
        // Per-node scratch for any tree over these primitives (fewer than `2 n` nodes).
        let nodes = 2 * bvh.prim_count();
        if s.counts.capacity() < nodes {
            s.counts.reserve_exact(nodes - s.counts.len());
        }
        if s.costs.capacity() < nodes {
            s.costs.reserve_exact(nodes - s.costs.len());
        }
        if s.heights.capacity() < nodes {
            s.heights.reserve_exact(nodes - s.heights.len());
        }
        prim_counts(bvh, &mut s.counts);
        heights(bvh, &mut s.heights);
        let limit = (bvh.prim_count() / CUT_TARGET).max(2 * bvh.max_leaf_size() as usize) as u32;
        // Every cut subtree's parent holds more than `limit` primitives, and fewer than
        // `2 n / limit` nodes do: room for the largest cut any tree over these primitives has,
        // so that taking the cut of a later build allocates nothing.
        let most = (4 * bvh.prim_count() / limit.max(1) as usize + 2).min(bvh.prim_count());
        if self.roots.capacity() < most {
            self.roots.reserve_exact(most);
            self.reference.reserve_exact(most);
            self.height.reserve_exact(most);
        }
        if s.work.capacity() < most {
            s.work.reserve_exact(most);
            s.order.reserve_exact(most);
            s.ranked.reserve_exact(most);
            s.emit.reserve_exact(2 * super::MAX_DEPTH + 2);
        }
        // Each thread's scratch grown to the largest cut subtree, so that rebuilding cut
        // subtrees allocates nothing whichever thread gets which.
        s.task_per_thread();
        for t in &mut s.tasks {
            let t = t.get_mut().unwrap_or_else(PoisonError::into_inner);
            if t.boxes.capacity() < limit as usize {
                t.grow(limit as usize, &BuildParams::BINNED);
            }
        }
        if s.boxes.capacity() < most {
            // The top's build over that many subtrees, once, so that its tree and scratch have
            // grown to it.
            s.boxes.clear();
            s.boxes.extend((0..most).map(|i| {
                let p = glam::Vec3::new(i as f32, (i % 7) as f32, (i % 3) as f32);
                Aabb::new(p, p + glam::Vec3::ONE)
            }));
            let params = BuildParams {
                max_leaf_size: 1,
                ..BuildParams::BINNED
            };
            s.top.rebuild(&s.boxes, &params, &mut s.build);
        }
        // Depth first from the root: a node within the limit (or a leaf) is a cut subtree.
        // Depth first: at most one pending sibling per level.
        s.stack.clear();
        s.stack.reserve(2 * super::MAX_DEPTH + 2);
        s.stack.push(0);
        while let Some(n) = s.stack.pop() {
            let node = &bvh.nodes()[n as usize];
            if node.is_leaf() || s.counts[n as usize] <= limit {
                self.roots.push(n);
            } else {
                s.stack.push(node.first + 1);
                s.stack.push(node.first);
            }
        }
        bvh.subtree_sah(SahCost::default(), &mut s.costs);
        self.reference
            .extend(self.roots.iter().map(|&r| s.costs[r as usize]));
        self.height
            .extend(self.roots.iter().map(|&r| s.heights[r as usize]));
    }
}

impl PartialCut {
    /// True when the cut's subtrees are subtrees of `bvh` whose primitive slots tile it, in
    /// order (as after [`PartialCut::reset`] and the partial rebuilds since).
    fn fits(&self, bvh: &Bvh) -> bool {
        let n = bvh.nodes().len() as u32;
        let mut next = 0;
        for &r in &self.roots {
            if r >= n {
                return false;
            }
            let (first, count) = bvh.slot_range(r);
            if first != next {
                return false;
            }
            next += count;
        }
        next as usize == bvh.prim_count()
            && self.roots.len() == self.reference.len()
            && self.roots.len() == self.height.len()
    }
}

impl MeshBvh {
    /// Rebuilds the top of the tree over `cut` and the worst cut subtrees holding at most
    /// `share` of the triangles (see the module docs); `cut` must have been taken from this
    /// tree's last full build ([`PartialCut::reset`]) and kept through every partial rebuild
    /// since. The chosen subtrees are rebuilt in parallel, each on one thread; the result is
    /// written straight into the builders' layout (each kept subtree's nodes moved as one
    /// block). Allocates nothing once the scratch has grown to the mesh.
    pub fn partial_rebuild(
        &mut self,
        cut: &mut PartialCut,
        share: f32,
        params: &BuildParams,
        ws: &mut RestructureWorkspace,
        s: &mut PartialScratch,
    ) -> PartialStats {
        let mut stats = PartialStats {
            cut: cut.len() as u32,
            ..PartialStats::default()
        };
        if !cut.fits(&self.bvh) {
            // Taken from another tree (or before an optimisation moved its subtrees): start
            // a new cut from this one, whose subtrees are then all as good as their reference.
            cut.reset(self, s);
            stats.cut = cut.len() as u32;
        }
        if cut.len() < 2 {
            return stats;
        }
        // Rank the cut subtrees by how far they degraded.
        self.bvh.subtree_sah(SahCost::default(), &mut s.costs);
        s.work.clear();
        s.ranked.clear();
        for (j, (&r, &reference)) in cut.roots.iter().zip(&cut.reference).enumerate() {
            let (first, count) = self.bvh.slot_range(r);
            s.work.push(CutWork {
                first,
                count,
                reference,
                height: cut.height[j],
                ..CutWork::default()
            });
            let now = s.costs[r as usize];
            if reference > 0.0 && now > reference * MIN_DEGRADATION {
                s.ranked.push((now / reference, j as u32));
            }
        }
        s.ranked
            .sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let allowed = (f64::from(share.clamp(0.0, 1.0)) * self.bvh.prim_count() as f64) as u64;
        let mut spent = 0u64;
        for &(_, j) in &s.ranked {
            let w = &mut s.work[j as usize];
            let k = u64::from(w.count);
            if spent + k > allowed {
                continue;
            }
            spent += k;
            w.rebuild = true;
            stats.rebuilt += 1;
            stats.rebuilt_tris += k as u32;
        }

        // The chosen subtrees rebuilt, their slots written into the scratch at their places
        // in their new order.
        let n = self.tris.len();
        ws.old_tris.resize(n, [glam::Vec3::ZERO; 3]);
        ws.old_prims.resize(n, 0);
        ws.old_leaf_indices.resize(n, [0; 3]);
        s.built.resize(2 * n, Node::default());
        s.task_per_thread();
        let sub_params = BuildParams {
            parallel_threshold: usize::MAX,
            ..*params
        };
        rebuild_chosen(
            &mut s.work,
            Slots {
                tris: &self.tris,
                prims: &self.bvh.prim_indices,
                indices: &self.leaf_indices,
            },
            SlotsMut {
                tris: &mut ws.old_tris,
                prims: &mut ws.old_prims,
                indices: &mut ws.old_leaf_indices,
            },
            &mut s.built,
            &sub_params,
            &s.tasks,
        );

        // The top over the cut subtrees' boxes, one subtree per leaf.
        s.boxes.clear();
        for (w, &r) in s.work.iter().zip(&cut.roots) {
            s.boxes.push(if w.rebuild {
                s.built[2 * w.first as usize].bounds()
            } else {
                self.bvh.nodes[r as usize].bounds()
            });
        }
        let top_params = BuildParams {
            max_leaf_size: 1,
            ..*params
        };
        s.top.rebuild(&s.boxes, &top_params, &mut s.build);
        if s.top.nodes().iter().any(|n| n.is_leaf() && n.count != 1) || !self.lay_out(cut, ws, s) {
            // Not one subtree per leaf, or deeper than a tree may be: nothing is changed.
            stats.rebuilt = 0;
            stats.rebuilt_tris = 0;
            return stats;
        }

        // The nodes and the slots in their new order; the cut subtrees' new roots, and the
        // rebuilt ones' new references.
        super::topology::take_or_copy(&mut self.bvh.nodes, &mut ws.nodes);
        // Only the rebuilt subtrees' slots and those the top moved are copied: the moved
        // kept ones into the scratch first (beside the rebuilt ones), then all of them to
        // their new places, which only they overlap.
        let range = |first: u32, count: u32| first as usize..(first + count) as usize;
        for w in s.work.iter().filter(|w| !w.rebuild && w.slot != w.first) {
            let from = range(w.first, w.count);
            ws.old_tris[from.clone()].copy_from_slice(&self.tris[from.clone()]);
            ws.old_prims[from.clone()].copy_from_slice(&self.bvh.prim_indices[from.clone()]);
            ws.old_leaf_indices[from.clone()].copy_from_slice(&self.leaf_indices[from]);
        }
        for w in s.work.iter().filter(|w| w.rebuild || w.slot != w.first) {
            let (from, to) = (range(w.first, w.count), range(w.slot, w.count));
            self.tris[to.clone()].copy_from_slice(&ws.old_tris[from.clone()]);
            self.bvh.prim_indices[to.clone()].copy_from_slice(&ws.old_prims[from.clone()]);
            self.leaf_indices[to].copy_from_slice(&ws.old_leaf_indices[from]);
        }
        // The cut in the new tree's order, so that its slots still tile the tree in order
        // and the next partial rebuild keeps it (with the kept subtrees' references).
        cut.clear();
        for &j in &s.order {
            let w = &s.work[j as usize];
            cut.roots.push(w.root);
            cut.reference.push(w.reference);
            cut.height.push(w.height);
        }
        stats
    }

    /// Writes the new tree into `ws.nodes` in the builders' layout: the top's interior nodes
    /// and, at each of its leaves, the cut subtree's nodes (the rebuilt tree from the scratch,
    /// or the kept one from this tree) as one block; records the cut subtrees in their new
    /// order (`s.order`) and each one's new root. Returns false (the tree then unchanged)
    /// when the result would be deeper than [`MAX_DEPTH`].
    fn lay_out(
        &self,
        cut: &PartialCut,
        ws: &mut RestructureWorkspace,
        s: &mut PartialScratch,
    ) -> bool {
        let nodes = &mut ws.nodes;
        nodes.clear();
        nodes.push(Node::default());
        s.order.clear();
        s.emit.clear();
        s.emit.push((0, 0, 0));
        let old = self.bvh.nodes();
        let mut slot = 0u32;
        while let Some((t, pos, depth)) = s.emit.pop() {
            let tn = s.top.nodes()[t as usize];
            if !tn.is_leaf() {
                if depth as usize >= MAX_DEPTH {
                    return false;
                }
                let q = nodes.len() as u32;
                nodes.push(Node::default());
                nodes.push(Node::default());
                nodes[pos as usize] = Node::interior(tn.bounds(), q);
                s.emit.push((tn.first + 1, q + 1, depth + 1));
                s.emit.push((tn.first, q, depth + 1));
                continue;
            }
            let j = s.top.prim_indices()[tn.first as usize] as usize;
            let w = &mut s.work[j];
            if depth as usize + w.height as usize > MAX_DEPTH {
                return false;
            }
            s.order.push(j as u32);
            w.root = pos;
            w.slot = slot;
            let base = nodes.len() as u32;
            // The block: its root and its descendants, which follow one another in the
            // builders' layout; (root, first descendant, end) in the source array.
            let (src, root, d0, d1) = if w.rebuild {
                let at = 2 * w.first as usize;
                (&s.built[..], at, at + 1, at + w.len as usize)
            } else {
                let r = cut.roots[j] as usize;
                if old[r].is_leaf() {
                    // No descendant (a leaf's `first` is a slot, not a node).
                    (old, r, 0, 0)
                } else {
                    (old, r, old[r].first as usize, descendants_end(old, r))
                }
            };
            // The rebuilt tree numbers its nodes and slots from 0 (its first descendant is
            // node 1); the kept one is numbered in this tree.
            let (first_slot, first_child) = if w.rebuild {
                (0, 1)
            } else {
                (w.first, d0 as u32)
            };
            let shift = |n: Node| -> Node {
                let mut n = n;
                if n.is_leaf() {
                    n.first = n.first - first_slot + slot;
                } else {
                    // The first descendant goes to `base`, the others after it in order.
                    n.first = n.first - first_child + base;
                }
                n
            };
            nodes[pos as usize] = shift(src[root]);
            nodes.extend(src[d0..d1].iter().map(|&n| shift(n)));
            slot += w.count;
        }
        true
    }
}

/// A cut subtree's part in a partial rebuild.
#[derive(Clone, Copy, Debug, Default)]
struct CutWork {
    /// Its primitive slots in the tree before.
    first: u32,
    count: u32,
    /// Chosen to be rebuilt.
    rebuild: bool,
    /// Its reference SAH (normalised by its root's area) and height: the cut's, or the
    /// rebuilt tree's; and the rebuilt tree's node count.
    reference: f32,
    height: u32,
    len: u32,
    /// Its root and its first slot in the new tree.
    root: u32,
    slot: u32,
}

/// One thread's scratch for rebuilding cut subtrees.
#[derive(Clone, Debug, Default)]
struct TaskScratch {
    boxes: Vec<Aabb>,
    sub: Bvh,
    build: BuildWorkspace,
    costs: Vec<f32>,
    heights: Vec<u32>,
}

impl TaskScratch {
    fn memory_bytes(&self) -> usize {
        use crate::bvh::held;
        held(&self.boxes)
            + self.sub.storage_bytes()
            + self.build.memory_bytes()
            + held(&self.costs)
            + held(&self.heights)
    }

    /// Grows every buffer to a subtree of `n` primitives, by building one.
    fn grow(&mut self, n: usize, params: &BuildParams) {
        self.boxes.clear();
        self.boxes.extend((0..n).map(|i| {
            let p = glam::Vec3::new(i as f32, (i % 7) as f32, (i % 3) as f32);
            Aabb::new(p, p + glam::Vec3::ONE)
        }));
        let serial = BuildParams {
            parallel_threshold: usize::MAX,
            ..*params
        };
        self.sub.rebuild(&self.boxes, &serial, &mut self.build);
        let nodes = 2 * n.max(1);
        if self.costs.capacity() < nodes {
            self.costs.reserve_exact(nodes - self.costs.len());
        }
        if self.heights.capacity() < nodes {
            self.heights.reserve_exact(nodes - self.heights.len());
        }
    }

    /// Rebuilds the subtree over `src`'s slots: writes them into `dst` in the new tree's
    /// order and its nodes (leaves numbering the slots from 0) into `built`; returns its node
    /// count, SAH and height.
    fn rebuild(
        &mut self,
        src: Slots<'_>,
        dst: SlotsMut<'_>,
        built: &mut [Node],
        params: &BuildParams,
    ) -> (u32, f32, u32) {
        self.boxes.clear();
        self.boxes.extend(src.tris.iter().map(Aabb::of_triangle));
        self.sub.rebuild(&self.boxes, params, &mut self.build);
        for (i, &p) in self.sub.prim_indices().iter().enumerate() {
            let p = p as usize;
            dst.tris[i] = src.tris[p];
            dst.prims[i] = src.prims[p];
            dst.indices[i] = src.indices[p];
        }
        let nodes = self.sub.nodes();
        built[..nodes.len()].copy_from_slice(nodes);
        self.sub.subtree_sah(SahCost::default(), &mut self.costs);
        heights(&self.sub, &mut self.heights);
        (nodes.len() as u32, self.costs[0], self.heights[0])
    }
}

/// A range of a mesh tree's slots: triangles, primitive ids, vertex indices.
#[derive(Clone, Copy)]
struct Slots<'a> {
    tris: &'a [[glam::Vec3; 3]],
    prims: &'a [u32],
    indices: &'a [[u32; 3]],
}

struct SlotsMut<'a> {
    tris: &'a mut [[glam::Vec3; 3]],
    prims: &'a mut [u32],
    indices: &'a mut [[u32; 3]],
}

impl Slots<'_> {
    /// Slots `first .. first + count`.
    fn range(self, first: u32, count: u32) -> Self {
        let r = first as usize..(first + count) as usize;
        Self {
            tris: &self.tris[r.clone()],
            prims: &self.prims[r.clone()],
            indices: &self.indices[r],
        }
    }
}

impl<'a> SlotsMut<'a> {
    fn split_at(self, k: usize) -> (Self, Self) {
        let (ta, tb) = self.tris.split_at_mut(k);
        let (pa, pb) = self.prims.split_at_mut(k);
        let (ia, ib) = self.indices.split_at_mut(k);
        (
            Self {
                tris: ta,
                prims: pa,
                indices: ia,
            },
            Self {
                tris: tb,
                prims: pb,
                indices: ib,
            },
        )
    }
}

/// Slots below which a part of the cut is done on one thread.
const SERIAL_SLOTS: usize = 4096;

/// Rebuilds the chosen cut subtrees of `work` (which tile `dst`'s slots in order; `src` is
/// every slot of the tree), in parallel: `dst` gets their slots, at the same places in their
/// new order, and `built` their nodes (the subtree at `dst`'s slot `f` from `2 f`).
fn rebuild_chosen(
    work: &mut [CutWork],
    src: Slots<'_>,
    dst: SlotsMut<'_>,
    built: &mut [Node],
    params: &BuildParams,
    tasks: &[Mutex<TaskScratch>],
) {
    if let [w] = work {
        if w.rebuild {
            let i = rayon::current_thread_index().unwrap_or(tasks.len() - 1);
            let mut t = tasks[i.min(tasks.len() - 1)]
                .lock()
                .unwrap_or_else(PoisonError::into_inner);
            let src = src.range(w.first, w.count);
            (w.len, w.reference, w.height) = t.rebuild(src, dst, built, params);
        }
        return;
    }
    let mid = work.len() / 2;
    let k = (work[mid].first - work[0].first) as usize;
    let serial = dst.tris.len() < SERIAL_SLOTS;
    let (wa, wb) = work.split_at_mut(mid);
    let (da, db) = dst.split_at(k);
    let (ba, bb) = built.split_at_mut(2 * k);
    if serial {
        rebuild_chosen(wa, src, da, ba, params, tasks);
        rebuild_chosen(wb, src, db, bb, params, tasks);
    } else {
        rayon::join(
            || rebuild_chosen(wa, src, da, ba, params, tasks),
            || rebuild_chosen(wb, src, db, bb, params, tasks),
        );
    }
}

/// The height of every subtree (0 for a leaf), into `out`.
fn heights(bvh: &Bvh, out: &mut Vec<u32>) {
    let nodes = bvh.nodes();
    out.clear();
    out.resize(nodes.len(), 0);
    for (i, n) in nodes.iter().enumerate().rev() {
        if !n.is_leaf() {
            out[i] = 1 + out[n.first as usize].max(out[n.first as usize + 1]);
        }
    }
}

/// Below this ratio to its reference a cut subtree is not worth rebuilding.
const MIN_DEGRADATION: f32 = 1.02;

/// Primitive count of every subtree, into `out`.
fn prim_counts(bvh: &Bvh, out: &mut Vec<u32>) {
    let nodes = bvh.nodes();
    out.clear();
    out.resize(nodes.len(), 0);
    for (i, n) in nodes.iter().enumerate().rev() {
        out[i] = if n.is_leaf() {
            n.count
        } else {
            out[n.first as usize] + out[n.first as usize + 1]
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::anim::generate::{Kind, generate};
    use glam::Vec3;

    /// The soup of the generated explosion at `w` of its target, and its triangles.
    fn explosion(w: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let g = generate(Kind::Explode, 6000, 1);
        let (a, b) = (&g.checks[0].1, &g.checks[1].1);
        let pos = a.iter().zip(b).map(|(a, b)| *a + w * (*b - *a)).collect();
        let tris = (0..a.len() as u32 / 3)
            .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
            .collect();
        (pos, tris)
    }

    /// Each cut subtree's reference, keyed by the least primitive id it holds.
    fn references(t: &MeshBvh, cut: &PartialCut) -> Vec<(u32, f32)> {
        let mut v: Vec<(u32, f32)> = cut
            .roots
            .iter()
            .zip(&cut.reference)
            .map(|(&r, &reference)| {
                let (first, count) = t.bvh().slot_range(r);
                let prims = &t.bvh().prim_indices()[first as usize..(first + count) as usize];
                (*prims.iter().min().unwrap(), reference)
            })
            .collect();
        v.sort_by_key(|e| e.0);
        v
    }

    #[test]
    fn the_cut_outlives_a_partial_rebuild_with_the_kept_subtrees_references() {
        let params = BuildParams::BINNED;
        let (p0, tris) = explosion(0.0);
        let mut t = MeshBvh::build_indexed(&p0, &tris, &params);
        let (mut ws, mut s) = (RestructureWorkspace::default(), PartialScratch::default());
        let mut cut = PartialCut::default();
        cut.reset(&t, &mut s);
        assert!(cut.len() > 16, "{} cut subtrees", cut.len());
        for (f, share) in [(0.2, 0.25), (0.4, 0.1), (0.7, 0.5)] {
            let (p, _) = explosion(f);
            t.refit_indexed(&p, &tris);
            let before = references(&t, &cut);
            let sah_before = t.bvh().sah_cost();
            let st = t.partial_rebuild(&mut cut, share, &params, &mut ws, &mut s);
            let sah_after = t.bvh().sah_cost();
            assert!(
                st.rebuilt > 0 && sah_after < sah_before,
                "{st:?} {sah_before} {sah_after}"
            );
            t.validate(&crate::geom::TriMesh::new(p.clone(), tris.clone()))
                .unwrap();
            // The cut still tiles the tree in order: the next partial rebuild keeps it.
            assert!(cut.fits(t.bvh()), "weight {f}");
            assert_eq!(cut.len(), before.len());
            let after = references(&t, &cut);
            let kept = before
                .iter()
                .zip(&after)
                .filter(|(b, a)| {
                    assert_eq!(a.0, b.0, "the same subtrees");
                    a.1 == b.1
                })
                .count();
            assert_eq!(kept, cut.len() - st.rebuilt as usize, "weight {f}: {st:?}");
        }
    }

    /// `n` small triangles in a row swaying by `w`, eight at each place, and one far from them:
    /// the top split puts that one in a leaf beside everything else, at the last slot.
    fn lopsided(n: usize, w: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut pos = Vec::new();
        for i in 0..=n {
            let c = if i < n {
                // Eight at each place: leaves of several triangles, fewer nodes than slots.
                let x = (i / 8) as f32 * 0.1;
                Vec3::new(x, w * (x + w).sin(), (i % 3) as f32 * 0.05)
            } else {
                Vec3::new(100.0 + i as f32, 50.0, 0.0)
            };
            pos.extend([c, c + Vec3::X * 0.05, c + Vec3::Y * 0.05]);
        }
        let tris = (0..pos.len() as u32 / 3)
            .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
            .collect();
        (pos, tris)
    }

    /// Meshes whose cuts hold leaves (a leaf whose parent is above the cut's limit): every
    /// share, on a chain of frames, gives a valid tree of the same triangles.
    #[test]
    fn cuts_holding_leaves() {
        let params = BuildParams::BINNED;
        let (mut ws, mut s) = (RestructureWorkspace::default(), PartialScratch::default());
        let mut leaf_roots = 0;
        for n in [16, 20, 33, 64, 130, 300, 700, 5000] {
            for share in [0.0, 0.25, 1.0] {
                let (p0, tris) = lopsided(n, 0.0);
                let mut t = MeshBvh::build_indexed(&p0, &tris, &params);
                let mut cut = PartialCut::default();
                cut.reset(&t, &mut s);
                leaf_roots += cut
                    .roots
                    .iter()
                    .filter(|&&r| t.bvh().nodes()[r as usize].is_leaf())
                    .count();
                for f in 1..=6 {
                    let (p, _) = lopsided(n, f as f32 / 6.0);
                    t.refit_indexed(&p, &tris);
                    t.partial_rebuild(&mut cut, share, &params, &mut ws, &mut s);
                    let mesh = crate::geom::TriMesh::new(p.clone(), tris.clone());
                    t.validate(&mesh)
                        .unwrap_or_else(|e| panic!("{n} triangles, share {share}, frame {f}: {e}"));
                    assert!(cut.len() < 2 || cut.fits(t.bvh()));
                }
            }
        }
        assert!(leaf_roots > 0, "no cut held a leaf");
    }
}
