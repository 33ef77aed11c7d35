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

use super::topology::{NONE, RestructureWorkspace};
use super::{BuildParams, BuildWorkspace, Bvh, MeshBvh, SahCost};
use crate::geom::Aabb;

/// Cut subtrees a mesh is split into (about; fewer for small meshes).
pub const CUT_TARGET: usize = 256;

/// A mesh's cut: the subtrees a partial rebuild keeps or rebuilds, and their reference SAH.
#[derive(Clone, Debug, Default)]
pub struct PartialCut {
    /// Root node of each cut subtree.
    roots: Vec<u32>,
    /// Each one's SAH normalised by its root's area when it was last built.
    reference: Vec<f32>,
}

/// What a partial rebuild did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PartialStats {
    /// Subtrees in the cut.
    pub cut: u32,
    /// Cut subtrees rebuilt from scratch, and their triangles.
    pub rebuilt: u32,
    pub rebuilt_tris: u32,
    /// The tree's SAH before and after.
    pub sah_before: f32,
    pub sah_after: f32,
}

/// Scratch of partial rebuilds, kept between calls.
#[derive(Clone, Debug, Default)]
pub struct PartialScratch {
    counts: Vec<u32>,
    costs: Vec<f32>,
    ranked: Vec<(f32, u32)>,
    stack: Vec<u32>,
    boxes: Vec<Aabb>,
    sub: Bvh,
    top: Bvh,
    build: BuildWorkspace,
    slot_prims: Vec<u32>,
    slot_tris: Vec<[glam::Vec3; 3]>,
    slot_indices: Vec<[u32; 3]>,
}

impl PartialCut {
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
    }

    /// Marks every cut subtree as degraded, so that the next partial rebuild of share 1
    /// rebuilds them all (to size scratch buffers ahead of the frame loop).
    pub fn mark_all_degraded(&mut self) {
        self.reference.fill(f32::MIN_POSITIVE);
    }

    /// Takes the cut of a freshly built tree. Allocates only to grow.
    pub fn reset(&mut self, tree: &MeshBvh, s: &mut PartialScratch) {
        self.roots.clear();
        self.reference.clear();
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
        prim_counts(bvh, &mut s.counts);
        let limit = (bvh.prim_count() / CUT_TARGET).max(2 * bvh.max_leaf_size() as usize) as u32;
        // Every cut subtree's parent holds more than `limit` primitives, and fewer than
        // `2 n / limit` nodes do: room for the largest cut any tree over these primitives has,
        // so that taking the cut of a later build allocates nothing.
        let most = (4 * bvh.prim_count() / limit.max(1) as usize + 2).min(bvh.prim_count());
        if self.roots.capacity() < most {
            self.roots.reserve_exact(most);
            self.reference.reserve_exact(most);
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
            let (first, count) = slot_range(bvh, r);
            if first != next {
                return false;
            }
            next += count;
        }
        next as usize == bvh.prim_count() && self.roots.len() == self.reference.len()
    }
}

impl MeshBvh {
    /// Rebuilds the top of the tree over `cut` and the worst cut subtrees holding at most
    /// `share` of the triangles (see the module docs); `cut` must have been taken from this
    /// tree's last full build ([`PartialCut::reset`]) and kept through every partial rebuild
    /// since. Allocates nothing once the scratch has grown to the mesh.
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
            sah_before: self.bvh.sah_cost(),
            ..PartialStats::default()
        };
        if !cut.fits(&self.bvh) {
            // Taken from another tree (or before an optimisation moved its subtrees): start
            // a new cut from this one, whose subtrees are then all as good as their reference.
            cut.reset(self, s);
            stats.cut = cut.len() as u32;
        }
        if cut.len() < 2 {
            stats.sah_after = stats.sah_before;
            return stats;
        }
        // Rank the cut subtrees by how far they degraded.
        self.bvh.subtree_sah(SahCost::default(), &mut s.costs);
        prim_counts(&self.bvh, &mut s.counts);
        s.ranked.clear();
        for (j, (&r, &reference)) in cut.roots.iter().zip(&cut.reference).enumerate() {
            let now = s.costs[r as usize];
            if reference > 0.0 && now > reference * MIN_DEGRADATION {
                s.ranked.push((now / reference, j as u32));
            }
        }
        s.ranked
            .sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let allowed = (f64::from(share.clamp(0.0, 1.0)) * self.bvh.prim_count() as f64) as u64;

        ws.topo.load(&self.bvh);
        let mut spent = 0u64;
        for i in 0..s.ranked.len() {
            let j = s.ranked[i].1 as usize;
            let root = cut.roots[j];
            let k = u64::from(s.counts[root as usize]);
            if spent + k > allowed {
                continue;
            }
            spent += k;
            self.rebuild_subtree(root, params, ws, s);
            // Marked rebuilt: it gets a new reference below.
            s.ranked[i].0 = -s.ranked[i].0;
            stats.rebuilt += 1;
            stats.rebuilt_tris += k as u32;
        }

        // The top over the cut subtrees' boxes, one subtree per leaf.
        s.boxes.clear();
        s.boxes
            .extend(cut.roots.iter().map(|&r| ws.topo.bounds[r as usize]));
        let top_params = BuildParams {
            max_leaf_size: 1,
            ..*params
        };
        s.top.rebuild(&s.boxes, &top_params, &mut s.build);
        if s.top.nodes().iter().any(|n| n.is_leaf() && n.count != 1) {
            // Not one subtree per leaf: nothing is changed.
            stats.sah_after = stats.sah_before;
            stats.rebuilt = 0;
            stats.rebuilt_tris = 0;
            return stats;
        }
        let base = ws.topo.len() as u32;
        let topo = &mut ws.topo;
        for n in s.top.nodes() {
            if n.is_leaf() {
                // A placeholder id: leaves are replaced by their cut subtree below.
                topo.push(n.bounds(), [NONE; 2], [0, 0]);
            } else {
                topo.push(n.bounds(), [base + n.first, base + n.first + 1], [0, 0]);
            }
        }
        let id = |t: &Bvh, n: u32| -> u32 {
            let node = &t.nodes()[n as usize];
            if node.is_leaf() {
                cut.roots[t.prim_indices()[node.first as usize] as usize]
            } else {
                base + n
            }
        };
        for (i, n) in s.top.nodes().iter().enumerate() {
            if !n.is_leaf() {
                let (l, r) = (id(&s.top, n.first), id(&s.top, n.first + 1));
                topo.link(base + i as u32, 0, l);
                topo.link(base + i as u32, 1, r);
            }
        }
        topo.root = id(&s.top, 0);
        topo.parent[topo.root as usize] = NONE;

        if self.apply_topology(ws) {
            // The cut subtrees' new roots; the rebuilt ones get a new reference.
            for r in &mut cut.roots {
                *r = ws.topo.position(*r);
            }
            self.bvh.subtree_sah(SahCost::default(), &mut s.costs);
            for i in 0..s.ranked.len() {
                let j = s.ranked[i].1 as usize;
                if s.ranked[i].0 < 0.0 {
                    cut.reference[j] = s.costs[cut.roots[j] as usize];
                }
            }
        }
        stats.sah_after = self.bvh.sah_cost();
        stats
    }

    /// Rebuilds the subtree at `root` (a node of the tree `ws.topo` was loaded from) from its
    /// triangles, reordering its primitive slots and grafting the new nodes into `ws.topo` in
    /// place of the old ones.
    fn rebuild_subtree(
        &mut self,
        root: u32,
        params: &BuildParams,
        ws: &mut RestructureWorkspace,
        s: &mut PartialScratch,
    ) {
        let (first, count) = slot_range(&self.bvh, root);
        let range = first as usize..(first + count) as usize;
        s.boxes.clear();
        s.boxes
            .extend(self.tris[range.clone()].iter().map(Aabb::of_triangle));
        s.sub.rebuild(&s.boxes, params, &mut s.build);
        // The slots in the new subtree's order.
        s.slot_prims.clear();
        s.slot_prims
            .extend_from_slice(&self.bvh.prim_indices[range.clone()]);
        s.slot_tris.clear();
        s.slot_tris.extend_from_slice(&self.tris[range.clone()]);
        s.slot_indices.clear();
        s.slot_indices
            .extend_from_slice(&self.leaf_indices[range.clone()]);
        for (i, &p) in s.sub.prim_indices().iter().enumerate() {
            let (dst, src) = (range.start + i, p as usize);
            self.bvh.prim_indices[dst] = s.slot_prims[src];
            self.tris[dst] = s.slot_tris[src];
            self.leaf_indices[dst] = s.slot_indices[src];
        }
        // Graft: the old root's id takes the new root; the other new nodes get new ids.
        let topo = &mut ws.topo;
        let base = topo.len() as u32;
        let nodes = s.sub.nodes();
        let id = |n: u32| if n == 0 { root } else { base + n - 1 };
        for n in &nodes[1..] {
            topo.push(n.bounds(), [NONE; 2], [0, 0]);
        }
        for (i, n) in nodes.iter().enumerate() {
            let me = id(i as u32);
            topo.bounds[me as usize] = n.bounds();
            if n.is_leaf() {
                topo.child[me as usize] = [NONE; 2];
                topo.leaf[me as usize] = [first + n.first, n.count];
            } else {
                topo.leaf[me as usize] = [0, 0];
                topo.link(me, 0, id(n.first));
                topo.link(me, 1, id(n.first + 1));
            }
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

/// The primitive slots of the subtree at `n`: (first, count).
fn slot_range(bvh: &Bvh, mut n: u32) -> (u32, u32) {
    let nodes = bvh.nodes();
    // Its first slot is its leftmost leaf's; its last, its rightmost leaf's end.
    let mut lo = n;
    while !nodes[lo as usize].is_leaf() {
        lo = nodes[lo as usize].first;
    }
    while !nodes[n as usize].is_leaf() {
        n = nodes[n as usize].first + 1;
    }
    let first = nodes[lo as usize].first;
    let last = &nodes[n as usize];
    (first, last.first + last.count - first)
}
