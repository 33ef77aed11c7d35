//! BVH construction. Builders see only primitive boxes (and their centroids), never triangles.
//!
//! Every builder writes the same layout: a node's two children are adjacent and come after it,
//! and every subtree owns a contiguous range of nodes and of primitive slots. While building, a
//! subtree over `n` primitives reserves `2n - 2` node slots for its descendants (the most a
//! binary tree with `n` leaves can need), so parallel subtrees write disjoint slices with no
//! locking; the unused slots are squeezed out at the end without changing the order. (The
//! binned builder packs each one-task subtree at the start of its slots and knows the count.)

mod binned;
pub mod clip;
mod median;
mod sweep;

use super::{Bvh, MAX_DEPTH, Node};
use crate::geom::Aabb;
use glam::Vec3A;
use rayon::prelude::*;
use wide::f32x8;

/// Which split strategy a build uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Binned SAH (Wald 2007): centroids sorted into `bins` buckets per axis.
    Binned,
    /// Full-sweep SAH: every split position on every axis, from presorted lists. The quality
    /// reference.
    Sweep,
    /// Cut the centroid-sorted primitives in the middle along the longest axis. The baseline.
    Median,
}

/// All the knobs of a build. The presets below are the ones the benchmarks report.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildParams {
    /// Split strategy.
    pub method: Method,
    /// Number of bins per axis for [`Method::Binned`] (2 ..= [`MAX_BINS`]).
    pub bins: usize,
    /// Bin on all three axes (true) or only on the widest axis of the centroid bounds.
    pub all_axes: bool,
    /// Largest number of primitives in a leaf.
    pub max_leaf_size: u32,
    /// SAH cost of visiting an interior node, relative to `intersection_cost`.
    pub traversal_cost: f32,
    /// SAH cost of intersecting one primitive.
    pub intersection_cost: f32,
    /// Subtrees with at least this many primitives are built as parallel tasks, and nodes with
    /// at least 8x as many are binned in parallel.
    pub parallel_threshold: usize,
}

/// The largest supported bin count.
pub const MAX_BINS: usize = 64;

impl BuildParams {
    /// Binned SAH with the default bin count: the builder dynbvh uses for rebuilds.
    ///
    /// Why 16 bins on all three axes: the builder bins while it partitions, so the bin count
    /// changes the build time little, and 16 bins come close to the full sweep's SAH; binning
    /// only the widest axis saves less build time than its worse trees cost in tracing. The
    /// runs are in `docs/build_speed.md`.
    pub const BINNED: BuildParams = BuildParams::binned(16);
    /// Full-sweep SAH: slowest, best quality.
    pub const SWEEP: BuildParams = BuildParams {
        method: Method::Sweep,
        ..BuildParams::BINNED
    };
    /// Median split: fastest, worst quality.
    pub const MEDIAN: BuildParams = BuildParams {
        method: Method::Median,
        max_leaf_size: 4,
        ..BuildParams::BINNED
    };

    /// Binned SAH with `bins` bins on every axis.
    #[must_use]
    pub const fn binned(bins: usize) -> BuildParams {
        BuildParams {
            method: Method::Binned,
            bins,
            all_axes: true,
            max_leaf_size: 8,
            traversal_cost: 1.0,
            intersection_cost: 1.0,
            parallel_threshold: 4096,
        }
    }

    /// A short name for reports: `binned16`, `binned16-widest`, `sweep`, `median`.
    #[must_use]
    pub fn name(&self) -> String {
        match self.method {
            Method::Binned if self.all_axes => format!("binned{}", self.bins),
            Method::Binned => format!("binned{}-widest", self.bins),
            Method::Sweep => "sweep".into(),
            Method::Median => "median".into(),
        }
    }
}

/// A primitive as builders see it, in one 32-byte vector: `[min.x, min.y, min.z, id, -max.x,
/// -max.y, -max.z, bins]` (`id` and `bins` as bit patterns). `bins` is scratch room for the
/// binned builder (the bin of its centroid on each axis, one byte each). With the upper corner
/// negated, the box of two such vectors is one lane-wise minimum (the id and bins lanes carry
/// junk through it and are never read as floats).
#[derive(Clone, Copy, Debug, bytemuck::Zeroable)]
#[repr(C)]
pub(crate) struct PrimRef {
    v: f32x8,
}

impl PrimRef {
    /// The reference to the box from `min` to `max`, sanitized as [`Aabb::sanitized`] does.
    #[inline(always)]
    fn from_corners(min: Vec3A, max: Vec3A, id: u32) -> Self {
        let m = Vec3A::splat(f32::MAX);
        let fix = |v: Vec3A, if_nan: Vec3A| Vec3A::select(v.is_nan_mask(), if_nan, v.clamp(-m, m));
        let (lo, hi) = (fix(min, m), -fix(max, -m));
        Self {
            v: f32x8::new([lo.x, lo.y, lo.z, f32::from_bits(id), hi.x, hi.y, hi.z, 0.0]),
        }
    }

    /// The primitive's index.
    #[inline(always)]
    pub fn id(&self) -> u32 {
        self.v.as_array()[3].to_bits()
    }

    /// The binned builder's scratch word.
    #[inline(always)]
    pub fn bins(&self) -> u32 {
        self.v.as_array()[7].to_bits()
    }

    #[inline(always)]
    pub fn set_bins(&mut self, bins: u32) {
        self.v.as_mut_array()[7] = f32::from_bits(bins);
    }

    /// `[min, -max]` as one vector.
    #[inline(always)]
    pub fn packed(&self) -> f32x8 {
        self.v
    }

    #[inline(always)]
    pub fn lo(&self) -> Vec3A {
        let a = self.v.as_array();
        Vec3A::new(a[0], a[1], a[2])
    }

    #[inline(always)]
    pub fn hi(&self) -> Vec3A {
        let a = self.v.as_array();
        -Vec3A::new(a[4], a[5], a[6])
    }

    /// Twice the centroid: builders compare centroids, and the factor 2 changes no order.
    #[inline(always)]
    pub fn c2(&self) -> Vec3A {
        self.lo() + self.hi()
    }
}

/// A box in SIMD-friendly form, used inside builders.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Box3 {
    pub min: Vec3A,
    pub max: Vec3A,
}

impl Box3 {
    pub const EMPTY: Box3 = Box3 {
        min: Vec3A::splat(f32::INFINITY),
        max: Vec3A::splat(f32::NEG_INFINITY),
    };

    #[inline(always)]
    pub fn grow(&mut self, lo: Vec3A, hi: Vec3A) {
        self.min = self.min.min(lo);
        self.max = self.max.max(hi);
    }

    #[inline(always)]
    pub fn grow_point(&mut self, p: Vec3A) {
        self.grow(p, p);
    }

    #[inline(always)]
    pub fn union(self, o: Box3) -> Box3 {
        Box3 {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    #[inline(always)]
    pub fn half_area(&self) -> f32 {
        let e = (self.max - self.min).max(Vec3A::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }

    /// [`Box3::half_area`] in `f64`, which does not overflow for any finite box.
    #[inline(always)]
    pub fn half_area_f64(&self) -> f64 {
        let e = (self.max - self.min).max(Vec3A::ZERO);
        let (x, y, z) = (f64::from(e.x), f64::from(e.y), f64::from(e.z));
        x * y + y * z + z * x
    }

    pub fn to_aabb(self) -> Aabb {
        Aabb::new(self.min.into(), self.max.into())
    }
}

/// Box and (doubled) centroid box of a range of references.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RangeBounds {
    pub bounds: Box3,
    pub cbounds: Box3,
}

impl RangeBounds {
    pub const EMPTY: RangeBounds = RangeBounds {
        bounds: Box3::EMPTY,
        cbounds: Box3::EMPTY,
    };

    #[inline(always)]
    pub fn add(&mut self, r: &PrimRef) {
        let (lo, hi) = (r.lo(), r.hi());
        self.bounds.grow(lo, hi);
        self.cbounds.grow_point(lo + hi);
    }

    fn merge(self, o: RangeBounds) -> RangeBounds {
        RangeBounds {
            bounds: self.bounds.union(o.bounds),
            cbounds: self.cbounds.union(o.cbounds),
        }
    }

    /// Bounds of `refs`, in parallel when there are many.
    pub fn of(refs: &[PrimRef], parallel_threshold: usize) -> RangeBounds {
        if refs.len() >= parallel_threshold.saturating_mul(8) {
            refs.par_chunks(parallel_threshold)
                .map(|c| RangeBounds::of(c, usize::MAX))
                .reduce(|| RangeBounds::EMPTY, RangeBounds::merge)
        } else {
            let mut rb = RangeBounds::EMPTY;
            for r in refs {
                rb.add(r);
            }
            rb
        }
    }
}

/// How a strategy split a node: `refs[..mid]` go left, the rest right; both sides non-empty.
pub(crate) struct Split {
    pub mid: usize,
    pub left: RangeBounds,
    pub right: RangeBounds,
}

/// A split strategy over references kept in one array (the median split; binned SAH has a
/// recursion of its own that bins the children while partitioning).
pub(crate) trait Splitter: Sync {
    /// Working memory a task reuses from node to node.
    type Scratch: Send;
    /// Fresh working memory, for a new task.
    fn scratch(&self) -> Self::Scratch;
    /// Partitions `refs` and returns the split, or `None` to make a leaf. It is called only
    /// with more than one primitive; returning `None` for more than `max_leaf_size` primitives
    /// makes the builder cut the range in the middle instead.
    fn split(
        &self,
        refs: &mut [PrimRef],
        rb: &RangeBounds,
        scratch: &mut Self::Scratch,
    ) -> Option<Split>;
}

/// Beyond this depth builders stop asking the strategy and halve ranges by count, so that the
/// tree's depth stays within [`MAX_DEPTH`] whatever the input.
pub(crate) const SAH_DEPTH_LIMIT: u32 = MAX_DEPTH as u32 - 40;

/// Makes every thread of the current rayon pool (the global pool outside one) ready to run
/// binned build tasks without allocating: each gets its spare bin stacks now (the builder keeps
/// them per thread; otherwise a thread makes its own the first time it runs a build task, with
/// several threads at whatever later build the scheduler first hands it one). Allocates, runs
/// on every thread of the pool: call it once, before a frame loop that must not allocate.
pub fn prepare_threads() {
    rayon::broadcast(|_| binned::warm_thread_spares());
}

/// Buffers a build needs besides the tree itself, kept from one build to the next so that a
/// rebuild with binned SAH or median split allocates nothing once they have grown (the full
/// sweep, a reference builder, still allocates its sorted lists).
#[derive(Clone, Debug, Default)]
pub struct BuildWorkspace {
    refs: Vec<PrimRef>,
    slots: Vec<Node>,
    /// The binned build's nodes split into tasks (`binned::build`).
    splits: Vec<[u32; 3]>,
    /// Set for a workspace used for one build and dropped: a build whose nodes are not
    /// compacted in parallel (on one thread, or not binned) then compacts them in place and
    /// hands the slot storage to a tree that has none, instead of copying them into fresh
    /// memory.
    pub(crate) one_shot: bool,
}

impl BuildWorkspace {
    /// A workspace for a single build (`Bvh::build`, `MeshBvh::build`).
    pub(crate) fn one_shot() -> Self {
        Self {
            one_shot: true,
            ..Self::default()
        }
    }
}

impl BuildWorkspace {
    /// Whether a build of `n` primitives with `params` fits in the storage held, so that it
    /// grows nothing.
    pub(crate) fn holds(&self, n: usize, params: &BuildParams) -> bool {
        let spare = if matches!(params.method, Method::Binned) {
            binned::regions_len(n, params, rayon::current_num_threads())
        } else {
            0
        };
        self.refs.capacity() >= n && self.slots.capacity() >= (2 * n).saturating_sub(1) + spare
    }

    /// Bytes held.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        use crate::bvh::held;
        held(&self.refs) + held(&self.slots) + held(&self.splits)
    }
}

impl Bvh {
    /// Builds a BVH over primitives given by their boxes; primitive `i` has box `boxes[i]`.
    #[must_use]
    pub fn build(boxes: &[Aabb], params: &BuildParams) -> Bvh {
        let mut bvh = Bvh::empty(params.max_leaf_size);
        bvh.rebuild(boxes, params, &mut BuildWorkspace::one_shot());
        bvh
    }

    /// Rebuilds this tree over new boxes (any count), reusing its storage and `ws`'s: once
    /// they have grown to the input's size, a binned or median rebuild allocates nothing.
    pub fn rebuild(&mut self, boxes: &[Aabb], params: &BuildParams, ws: &mut BuildWorkspace) {
        self.rebuild_from(
            boxes.len(),
            |refs, base| {
                let mut rb = RangeBounds::EMPTY;
                for (i, (r, b)) in refs.iter_mut().zip(&boxes[base..]).enumerate() {
                    *r = PrimRef::from_corners(b.min.into(), b.max.into(), (base + i) as u32);
                    rb.add(r);
                }
                rb
            },
            params,
            ws,
        );
    }

    /// [`Bvh::rebuild`] over `n` primitives whose references `fill` makes: `fill(refs, base)`
    /// writes the references of primitives `base .. base + refs.len()` into `refs` and returns
    /// their bounds. Each box is made where the builder reads it, with no array of boxes in
    /// between (`MeshBvh` bounds its triangles here, with [`refs_from_corners`]).
    pub(crate) fn rebuild_from(
        &mut self,
        n: usize,
        fill: impl Fn(&mut [PrimRef], usize) -> RangeBounds + Sync,
        params: &BuildParams,
        ws: &mut BuildWorkspace,
    ) {
        self.rebuild_split::<median::Median>(n, fill, None, params, ws);
    }

    /// [`Bvh::rebuild_from`] with `splitter`, when given, in place of `params.method`'s (the
    /// clip-aware build, [`clip`]); `params` still gives the leaf size and the parallelism.
    pub(crate) fn rebuild_split<S: Splitter>(
        &mut self,
        n: usize,
        fill: impl Fn(&mut [PrimRef], usize) -> RangeBounds + Sync,
        splitter: Option<&S>,
        params: &BuildParams,
        ws: &mut BuildWorkspace,
    ) {
        // A threshold of 0 would ask for chunks of no element.
        let params = &BuildParams {
            parallel_threshold: params.parallel_threshold.max(1),
            ..*params
        };
        self.max_leaf_size = params.max_leaf_size;
        self.prim_indices.clear();
        if n == 0 {
            self.nodes.clear();
            return;
        }
        let refs = &mut ws.refs;
        // Every reference is written below and every used slot is written before it is read,
        // so old contents are kept: only growth initialises memory.
        grow_zeroed(refs, n);
        refs.truncate(n);
        // The references, and the root's bounds gathered on the way.
        let rb = if n >= params.parallel_threshold.saturating_mul(8) {
            refs.par_chunks_mut(params.parallel_threshold)
                .enumerate()
                .map(|(c, r)| fill(r, c * params.parallel_threshold))
                .reduce(|| RangeBounds::EMPTY, RangeBounds::merge)
        } else {
            fill(refs, 0)
        };
        let slots = &mut ws.slots;
        let binned = splitter.is_none() && matches!(params.method, Method::Binned);
        let threads = rayon::current_num_threads();
        let spare = if binned {
            binned::regions_len(n, params, threads)
        } else {
            0
        };
        let total = 2 * n - 1 + spare;
        if grow_zeroed(slots, total) && binned {
            // A binned build on one thread writes its nodes in order from the first slot, and
            // a parallel one nearly all of them into its threads' regions, each from its start:
            // on huge pages that takes a fault per 2 MiB of them instead of per 4 KiB, and the
            // rest is never touched (the reserved slots of a parallel build, which hold only
            // its few task splits, are left on small pages).
            if threads == 1 {
                crate::simd::advise_huge_vec(slots);
            } else {
                crate::simd::advise_huge_slice(&mut slots[2 * n - 1..total]);
            }
        }
        let (root, desc) = slots[..total].split_at_mut(1);
        let (desc, spare_slots) = desc.split_at_mut(2 * n - 2);
        let (count, packed);
        // The binned build's task splits, by which its slots compact in parallel.
        let mut split_slots = false;
        (root[0], count, packed) = match (splitter, params.method) {
            (Some(s), _) => (build_range(s, params, refs, rb, desc), None, false),
            (None, Method::Binned) => {
                let (root, count, packed) = binned::build(
                    params,
                    refs,
                    rb,
                    desc,
                    (spare_slots, 2 * n - 1),
                    &mut ws.splits,
                );
                split_slots = true;
                (root, Some(count), packed)
            }
            (None, Method::Median) => {
                let m = median::Median(params.max_leaf_size as usize);
                (build_range(&m, params, refs, rb, desc), None, false)
            }
            (None, Method::Sweep) => (sweep::build(params, refs, desc), None, false),
        };
        if n >= params.parallel_threshold.saturating_mul(8) {
            // Written in place by parallel chunks.
            self.prim_indices
                .par_extend(refs.par_iter().map(PrimRef::id));
        } else {
            self.prim_indices.extend(refs.iter().map(PrimRef::id));
        }
        if let (true, false, Some(count)) = (split_slots, packed, count) {
            // A parallel binned build: its packed subtrees are copied in blocks, in parallel.
            if self.nodes.capacity() == 0 {
                // A cold build: fresh zeroed pages, as huge pages where they are large
                // (faulted by the threads that write them), with the headroom of `compact`.
                self.nodes = crate::simd::zeroed_huge(count, node_room(count, 2 * n - 1));
            } else {
                if count > self.nodes.capacity() {
                    self.nodes.clear();
                    self.nodes.reserve_exact(node_room(count, 2 * n - 1));
                }
                // Every node is written below: the old tree's need not be cleared first.
                self.nodes
                    .resize(count, <Node as bytemuck::Zeroable>::zeroed());
            }
            compact_split(&slots[..total], &ws.splits, &mut self.nodes);
        } else if ws.one_shot && self.nodes.capacity() == 0 {
            // A cold build: no copy into fresh pages.
            let mut slots = std::mem::take(&mut ws.slots);
            slots.truncate(2 * n - 1);
            if packed {
                // Already in final order: the tree is the slots' first `count`.
                slots.truncate(count.unwrap_or(2 * n - 1));
            } else {
                compact_in_place(&mut slots, count);
            }
            let count = slots.len();
            slots.shrink_to(node_room(count, 2 * n - 1));
            self.nodes = slots;
        } else if let (true, Some(count)) = (packed, count) {
            debug_assert_eq!(count, count_nodes(&slots[..2 * n - 1], 0));
            self.nodes.clear();
            if count > self.nodes.capacity() {
                self.nodes.reserve_exact(node_room(count, 2 * n - 1));
            }
            self.nodes.extend_from_slice(&slots[..count]);
        } else {
            self.nodes.clear();
            compact(&slots[..2 * n - 1], count, &mut self.nodes);
        }
    }
}

/// Writes the references of primitives `base ..` into `refs`, their boxes given by `corners_of`
/// (lower and upper corner, sanitized here as [`Aabb::sanitized`] does), and returns their
/// bounds: a `fill` for [`Bvh::rebuild_from`].
#[inline]
pub(crate) fn refs_from_corners(
    refs: &mut [PrimRef],
    base: usize,
    corners_of: impl Fn(usize) -> (Vec3A, Vec3A),
) -> RangeBounds {
    let mut rb = RangeBounds::EMPTY;
    for (i, r) in refs.iter_mut().enumerate() {
        let id = base + i;
        let (min, max) = corners_of(id);
        *r = PrimRef::from_corners(min, max, id as u32);
        rb.add(r);
    }
    rb
}

/// Makes `v` at least `len` long. New storage is allocated zeroed (by the system, page by page
/// on first touch, for large sizes) rather than filled: a cold 1M build would otherwise write
/// 64 MB of node slots, most of which it never uses, and 32 MB of references it overwrites.
/// Returns true when the storage is new (nothing of it touched yet).
pub(crate) fn grow_zeroed<T: bytemuck::Zeroable + Clone>(v: &mut Vec<T>, len: usize) -> bool {
    if v.capacity() < len {
        *v = bytemuck::zeroed_vec(len);
        return true;
    }
    if v.len() < len {
        v.resize(len, T::zeroed());
    }
    false
}

/// Builds the whole tree over `refs` with one splitter: writes the root's descendants into
/// `desc` (global indices from 1) and returns the root.
fn build_range<S: Splitter>(
    splitter: &S,
    params: &BuildParams,
    refs: &mut [PrimRef],
    rb: RangeBounds,
    desc: &mut [Node],
) -> Node {
    let mut scratch = splitter.scratch();
    let b = Recursion { splitter, params };
    b.node(
        refs,
        rb,
        Slots {
            prim_offset: 0,
            desc,
            desc_base: 1,
        },
        0,
        &mut scratch,
    )
}

/// Where a subtree goes: its first primitive slot, and the node slots reserved for its
/// descendants (`2n - 2` of them; the global index of `desc[0]` is `desc_base`).
struct Slots<'a> {
    prim_offset: u32,
    desc: &'a mut [Node],
    desc_base: u32,
}

struct Recursion<'a, S> {
    splitter: &'a S,
    params: &'a BuildParams,
}

impl<S: Splitter> Recursion<'_, S> {
    fn node(
        &self,
        refs: &mut [PrimRef],
        rb: RangeBounds,
        out: Slots<'_>,
        depth: u32,
        scratch: &mut S::Scratch,
    ) -> Node {
        let n = refs.len();
        let bounds = rb.bounds.to_aabb();
        if n == 1 {
            return Node::leaf(bounds, out.prim_offset, 1);
        }
        let split = if depth < SAH_DEPTH_LIMIT {
            self.splitter.split(refs, &rb, scratch)
        } else {
            None
        };
        let split = match split {
            Some(sp) => sp,
            None if n <= self.params.max_leaf_size as usize => {
                return Node::leaf(bounds, out.prim_offset, n as u32);
            }
            None => halve(refs, self.params.parallel_threshold),
        };
        let mid = split.mid;
        debug_assert!(mid > 0 && mid < n);
        let (pair, rest) = out.desc.split_at_mut(2);
        let (ldesc, rdesc) = rest.split_at_mut(2 * mid - 2);
        let (lrefs, rrefs) = refs.split_at_mut(mid);
        let lbase = out.desc_base + 2;
        let left = Slots {
            prim_offset: out.prim_offset,
            desc: ldesc,
            desc_base: lbase,
        };
        let right = Slots {
            prim_offset: out.prim_offset + mid as u32,
            desc_base: lbase + 2 * mid as u32 - 2,
            desc: rdesc,
        };
        let (l, r) = if n >= self.params.parallel_threshold {
            rayon::join(
                || self.node(lrefs, split.left, left, depth + 1, scratch),
                || {
                    self.node(
                        rrefs,
                        split.right,
                        right,
                        depth + 1,
                        &mut self.splitter.scratch(),
                    )
                },
            )
        } else {
            (
                self.node(lrefs, split.left, left, depth + 1, scratch),
                self.node(rrefs, split.right, right, depth + 1, scratch),
            )
        };
        pair[0] = l;
        pair[1] = r;
        Node::interior(bounds, out.desc_base)
    }
}

/// Puts `refs` in the order of their primitive indices (at once if they are in it). The binned
/// builder's parallel partition leaves each side's references in another order than the serial
/// one; every choice it makes from a node's order (a leaf's triangle order, a small node's
/// ties, a cut by count) is made from this order, so that the tree does not depend on the
/// number of threads.
pub(crate) fn in_id_order(refs: &mut [PrimRef]) {
    if !refs.is_sorted_by_key(PrimRef::id) {
        refs.sort_unstable_by_key(PrimRef::id);
    }
}

/// Cuts a range in the middle by count, as it is: the fallback when no split by position is
/// possible (all centroids in one point) or the depth limit is reached.
fn halve(refs: &[PrimRef], parallel_threshold: usize) -> Split {
    let mid = refs.len() / 2;
    Split {
        mid,
        left: RangeBounds::of(&refs[..mid], parallel_threshold),
        right: RangeBounds::of(&refs[mid..], parallel_threshold),
    }
}

/// Copies the nodes out of the reserved slots into `out`, skipping the slots no node was
/// written to. Slots hold each subtree as "children pair, left child's descendants, right
/// child's descendants", so a pre-order walk over pairs emits the nodes in slot order: the
/// order, and with it every invariant, is kept. `count` is the tree's node count if the builder
/// knows it.
fn compact(slots: &[Node], count: Option<usize>, out: &mut Vec<Node>) {
    let count = count.unwrap_or_else(|| count_nodes(slots, 0));
    debug_assert_eq!(count, count_nodes(slots, 0));
    if count > out.capacity() {
        out.reserve_exact(node_room(count, slots.len()));
    }
    out.push(slots[0]);
    if !slots[0].is_leaf() {
        emit_pair(slots, 0, out);
    }
}

/// Room for a tree of `count` nodes: 1/8 headroom plus a few nodes, but never past `most`, the
/// most a tree over these primitives can have. Rebuilds of a deforming mesh vary in node count
/// by a few per cent, and a small tree (a top-level tree over a few instances) by a few nodes,
/// and then fit without reallocating.
fn node_room(count: usize, most: usize) -> usize {
    (count + count / 8 + 8).min(most).max(count)
}

/// [`compact`] of a parallel binned build's slots into `out` (as long as the tree; every node
/// is written): `splits` are its nodes split into two tasks, sorted by the slot of their
/// children's pair, with both children's descendant counts; every other subtree is packed in
/// its slots ("children pair, left child's descendants, right child's descendants", with no
/// gap), so it is copied as one block, its interior nodes' child indices moved by where the
/// block lands. Blocks and the split nodes' two sides are written in parallel; the nodes and
/// their order are [`compact`]'s.
fn compact_split(slots: &[Node], splits: &[[u32; 3]], out: &mut [Node]) {
    out[0] = slots[0];
    if slots[0].is_leaf() {
        return;
    }
    out[0].first = 1;
    let rest = &mut out[1..];
    emit_subtree(slots, splits, 1, rest, 1);
}

/// Writes into `out` (starting at node index `base`) the descendants of the node whose
/// children's pair is at slot `c`: its pair, then each child's descendants.
fn emit_subtree(slots: &[Node], splits: &[[u32; 3]], c: usize, out: &mut [Node], base: u32) {
    let Ok(k) = splits.binary_search_by_key(&(c as u32), |s| s[0]) else {
        // Packed: the whole block, children indices moved from slot `c` to `base`.
        let len = out.len();
        for (o, s) in out.iter_mut().zip(&slots[c..c + len]) {
            *o = *s;
            if !s.is_leaf() {
                o.first = s.first - c as u32 + base;
            }
        }
        return;
    };
    let [_, lcount, rcount] = splits[k];
    let (pair, rest) = out.split_at_mut(2);
    let (lout, rout) = rest.split_at_mut(lcount as usize);
    debug_assert_eq!(rout.len(), rcount as usize);
    pair[0] = slots[c];
    pair[1] = slots[c + 1];
    let (lbase, rbase) = (base + 2, base + 2 + lcount);
    let (lc, rc) = (pair[0].first as usize, pair[1].first as usize);
    if !pair[0].is_leaf() {
        pair[0].first = lbase;
    }
    if !pair[1].is_leaf() {
        pair[1].first = rbase;
    }
    rayon::join(
        || {
            if !lout.is_empty() {
                emit_subtree(slots, splits, lc, lout, lbase);
            }
        },
        || {
            if !rout.is_empty() {
                emit_subtree(slots, splits, rc, rout, rbase);
            }
        },
    );
}

/// [`compact`] within the slots themselves (truncated to the tree): the walk emits nodes in
/// slot order, so each pair is written at or before the slots it is read from, and no slot
/// still to be read is overwritten.
fn compact_in_place(slots: &mut Vec<Node>, count: Option<usize>) {
    let mut len = 1;
    if !slots[0].is_leaf() {
        emit_pair_in_place(slots, 0, &mut len);
    }
    debug_assert!(count.is_none_or(|c| c == len));
    slots.truncate(len);
}

/// [`emit_pair`] in place: `len` nodes are emitted so far.
fn emit_pair_in_place(s: &mut [Node], parent: usize, len: &mut usize) {
    let c = slots_child(s[parent]);
    let at = *len;
    debug_assert!(at <= c);
    let pair = [s[c], s[c + 1]];
    s[parent].first = at as u32;
    s[at] = pair[0];
    s[at + 1] = pair[1];
    *len += 2;
    for k in [at, at + 1] {
        if !s[k].is_leaf() {
            emit_pair_in_place(s, k, len);
        }
    }
}

/// Emits the children of the node already written at `out[parent]` and their subtrees.
fn emit_pair(slots: &[Node], parent: usize, out: &mut Vec<Node>) {
    let c = slots_child(out[parent]);
    let at = out.len();
    out[parent].first = at as u32;
    out.push(slots[c]);
    out.push(slots[c + 1]);
    for k in [at, at + 1] {
        if !out[k].is_leaf() {
            // `out[k].first` still holds the slot index of its children until emitted.
            emit_pair(slots, k, out);
        }
    }
}

/// Number of nodes in the subtree at slot `i`.
fn count_nodes(slots: &[Node], i: usize) -> usize {
    let n = slots[i];
    if n.is_leaf() {
        1
    } else {
        1 + count_nodes(slots, n.first as usize) + count_nodes(slots, n.first as usize + 1)
    }
}

/// The slot index of a not yet emitted interior node's children.
fn slots_child(n: Node) -> usize {
    n.first as usize
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// Boxes of a bumpy shell with clusters (uneven subtrees) and repeated centroids.
    fn boxes(n: usize) -> Vec<Aabb> {
        (0..n)
            .map(|i| {
                let t = i as f32 * 0.618_034;
                let r = 1.0 + 0.3 * (t * 7.0).sin() + if i % 97 < 9 { 5.0 } else { 0.0 };
                let c = Vec3::new(t.cos() * r, (t * 1.3).sin() * r, (i % 13) as f32 * 0.01);
                let c = if i % 211 == 0 { Vec3::splat(0.5) } else { c };
                Aabb::new(c - Vec3::splat(0.01), c + Vec3::splat(0.02))
            })
            .collect()
    }

    #[test]
    fn the_parallel_compaction_writes_the_serial_ones_nodes() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("pool");
        for (n, threshold) in [
            (1, 2),
            (7, 2),
            (300, 2),
            (5_000, 16),
            (60_000, 512),
            (3_000, 4096),
        ] {
            let p = BuildParams {
                parallel_threshold: threshold,
                ..BuildParams::binned(16)
            };
            let b = boxes(n);
            pool.install(|| {
                let refs: Vec<PrimRef> = b
                    .iter()
                    .enumerate()
                    .map(|(i, b)| PrimRef::from_corners(b.min.into(), b.max.into(), i as u32))
                    .collect();
                let rb = RangeBounds::of(&refs, threshold);
                // The threads' regions as the build sizes them, one eighth of that (some
                // subtrees then go into their reserved slots), and none.
                let full = binned::regions_len(n, &p, 2);
                let mut trees = Vec::new();
                for spare in [full, full / 8, 0] {
                    let mut refs = refs.clone();
                    let mut slots = vec![<Node as bytemuck::Zeroable>::zeroed(); 2 * n - 1 + spare];
                    let mut splits = Vec::new();
                    let (root, desc) = slots.split_at_mut(1);
                    let (desc, regions) = desc.split_at_mut(2 * n - 2);
                    let (count, packed);
                    (root[0], count, packed) =
                        binned::build(&p, &mut refs, rb, desc, (regions, 2 * n - 1), &mut splits);
                    assert!(!packed || splits.is_empty());
                    let mut serial = Vec::new();
                    compact(&slots, Some(count), &mut serial);
                    let mut parallel = vec![<Node as bytemuck::Zeroable>::zeroed(); count];
                    compact_split(&slots, &splits, &mut parallel);
                    assert_eq!(serial.len(), count, "{n}");
                    for (i, (a, b)) in serial.iter().zip(&parallel).enumerate() {
                        assert_eq!(a, b, "{n} boxes, threshold {threshold}: node {i}");
                    }
                    if n >= 5_000 {
                        // Subtrees went into the regions when there were any: all of them
                        // into regions of the full size (the reserved slots hold only the root
                        // and the task splits' pairs), some into reserved slots with an eighth.
                        let in_regions = slots[2 * n - 1..].iter().filter(|s| s.max[0] != 0.0);
                        let in_regions = in_regions.count();
                        assert_eq!(in_regions > 0, spare > 0, "{n}, regions of {spare}");
                        let reserved = count - in_regions;
                        let fell_back = reserved > 1 + 2 * splits.len();
                        assert_eq!(fell_back, spare < full, "{n}, regions of {spare}");
                        assert!(splits.len() > 4, "{n}: {} task splits", splits.len());
                    }
                    trees.push(serial);
                }
                assert!(trees.windows(2).all(|w| w[0] == w[1]), "{n}");
            });
        }
    }
}
