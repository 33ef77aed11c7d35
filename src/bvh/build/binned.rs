//! Binned SAH (Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies", 2007),
//! with the partition of a node fused with the binning of its two children.
//!
//! A plain binned builder reads every primitive twice per level: once to bin it, once to
//! partition it. Here only the root (and any node reached by a fallback split) is binned on
//! its own; every SAH split bins each primitive into its child's bins while partitioning. A
//! child's bin map must be chosen before its primitives are seen, so it is predicted from what
//! is known then: the parent's centroid bounds cut at the chosen bin boundary, intersected with
//! the child's box (exact: the union of its bins). Any monotone map gives valid bins; a
//! predicted map only spreads the child's centroids over somewhat fewer bins than its exact
//! centroid bounds would.
//!
//! Subtrees of at most [`SMALL`] primitives are never binned: their parent's partition skips
//! them and [`Ctx::small_node`] prices every way to cut them. Large nodes bin into two sets
//! per side taken in turn ([`partition_bin_dual`]).

use super::{
    Box3, BuildParams, MAX_BINS, Node, PrimRef, RangeBounds, SAH_DEPTH_LIMIT, Slots, halve,
    in_id_order,
};
use bytemuck::Zeroable;
use glam::{BVec3A, Vec3A};
use rayon::prelude::*;
use std::sync::{Mutex, PoisonError};
use wide::{f32x8, i32x8};

/// Nodes of at most this many primitives are split by pricing every way to cut them
/// ([`Ctx::small_node`]) rather than by binning.
const SMALL: usize = 6;
// `Ctx::small_node` builds its subset boxes from tables over the first three and the rest.
const _: () = assert!(SMALL >= 3 && SMALL <= 8);

/// The binned builder's settings.
struct Ctx<'s> {
    bins: usize,
    all_axes: bool,
    traversal_cost: f32,
    intersection_cost: f32,
    max_leaf_size: usize,
    parallel_threshold: usize,
    /// The pool's thread count. With one thread no subtree is made a task of its own: the
    /// whole tree is packed, already in its final order.
    threads: usize,
    /// Each node split into two tasks: the slot of its children's pair and their descendant
    /// counts (for [`super::compact_split`]).
    splits: Mutex<Vec<[u32; 3]>>,
    /// Each pool thread's region of node slots, by thread index (the first [`MAX_REGIONS`]
    /// threads; in a fixed array, so that a build allocates nothing for them): the subtrees a
    /// thread builds alone go there, one after another, when it has room (see
    /// [`Ctx::subtree`]).
    regions: [Option<Mutex<Region<'s>>>; MAX_REGIONS],
}

/// The most threads that get a region of their own; the others build into their subtrees'
/// reserved slots.
const MAX_REGIONS: usize = 64;

/// A run of node slots that one thread fills from its start, subtree after subtree.
struct Region<'s> {
    nodes: &'s mut [Node],
    /// The global slot index of `nodes[0]`.
    base: u32,
    /// Slots written so far.
    used: usize,
}

/// Builds the tree over `refs` (reordered into leaf order on return); writes the descendants of
/// the root into `desc` and returns the root, the tree's node count, and whether the nodes are
/// packed (the tree is then `[root, desc[..count - 1]]` as it stands, in its final order:
/// a build on one thread runs no task and packs every subtree). `splits` receives, sorted,
/// the nodes split into two tasks: the slot of the children's pair and the two children's
/// descendant counts; every other subtree is packed in its slots.
/// `rb` bounds `refs`. `regions`, a run of slots and the global slot index of its first, is
/// split among the pool's threads for the subtrees each builds alone ([`regions_len`] slots
/// are enough).
pub(crate) fn build(
    p: &BuildParams,
    refs: &mut [PrimRef],
    rb: RangeBounds,
    desc: &mut [Node],
    regions: (&mut [Node], usize),
    splits: &mut Vec<[u32; 3]>,
) -> (Node, usize, bool) {
    let threads = rayon::current_num_threads();
    let (spare, spare_base) = regions;
    let per_thread = spare.len() / threads.clamp(1, MAX_REGIONS);
    let mut chunks = spare.chunks_mut(per_thread.max(1)).enumerate();
    let regions = std::array::from_fn(|_| {
        let (t, nodes) = chunks.next().filter(|_| per_thread > 0)?;
        Some(Mutex::new(Region {
            nodes,
            base: (spare_base + t * per_thread) as u32,
            used: 0,
        }))
    });
    splits.clear();
    // A node split into tasks holds at least `parallel_threshold` references; room for as
    // many as a tree whose nodes of that size are all split in two, kept for later builds.
    splits.reserve(2 * refs.len() / p.parallel_threshold.max(1) + 2);
    let ctx = Ctx {
        splits: Mutex::new(std::mem::take(splits)),
        bins: p.bins.clamp(2, MAX_BINS),
        all_axes: p.all_axes,
        traversal_cost: p.traversal_cost,
        intersection_cost: p.intersection_cost,
        max_leaf_size: p.max_leaf_size.max(1) as usize,
        parallel_threshold: p.parallel_threshold.max(1),
        threads,
        regions,
    };
    let info = Info {
        bounds: rb.bounds,
        cbounds: rb.cbounds,
        map: None,
    };
    let mut stack = Stack::take();
    let (root, desc_count) = ctx.node(
        refs,
        info,
        Slots {
            prim_offset: 0,
            desc,
            desc_base: 1,
        },
        0,
        &mut stack,
        0,
        0,
    );
    *splits = ctx
        .splits
        .into_inner()
        .unwrap_or_else(PoisonError::into_inner);
    splits.sort_unstable_by_key(|s| s[0]);
    (root, desc_count as usize + 1, ctx.threads == 1)
}

/// Bins on the three axes, each one vector: its box in the `[min, -max]` form of
/// [`PrimRef::packed`] (lanes 0-2 and 4-6, so that growing it is a single lane-wise minimum) and
/// its count, as integer bits, in lane 7 (lane 3 is junk); only the first `k` of each axis are
/// in use.
#[derive(Clone, Copy)]
struct Bins {
    b: [[f32x8; MAX_BINS]; 3],
}

/// The empty box in `[min, -max]` form.
const EMPTY8: f32x8 = f32x8::new([f32::INFINITY; 8]);

/// An empty bin: the empty box, count 0.
const EMPTY_BIN: f32x8 = {
    let mut v = [f32::INFINITY; 8];
    v[7] = 0.0;
    f32x8::new(v)
};

/// Added to a bin's integer bits, adds 1 to its count and nothing elsewhere.
const COUNT_ONE: i32x8 = i32x8::new([0, 0, 0, 0, 0, 0, 0, 1]);

/// Selects a bin's count lane from its integer bits.
const COUNT_MASK: i32x8 = i32x8::new([0, 0, 0, 0, 0, 0, 0, -1]);

/// A lane-wise maximum with this keeps a box's lanes and makes lane 7 `+inf`, so that a minimum
/// of a bin with the result leaves the bin's count as it is (a count's bits, as a float, are
/// below infinity).
const KEEP_COUNT: f32x8 = {
    let mut v = [f32::NEG_INFINITY; 8];
    v[7] = f32::INFINITY;
    f32x8::new(v)
};

const EMPTY_BINS: Bins = Bins {
    b: [[EMPTY_BIN; MAX_BINS]; 3],
};

/// A bin's count.
#[inline(always)]
fn count_of(bin: f32x8) -> u32 {
    bin.as_array()[7].to_bits()
}

/// The union of two bins: the box around both, the sum of their counts.
#[inline(always)]
fn merge_bin(a: f32x8, b: f32x8) -> f32x8 {
    let counts: f32x8 = bytemuck::cast(
        bytemuck::cast::<_, i32x8>(a) + (bytemuck::cast::<_, i32x8>(b) & COUNT_MASK),
    );
    counts.fast_min(b.fast_max(KEEP_COUNT))
}

/// A `[min, -max]` box as a [`Box3`].
#[inline(always)]
fn unpack(v: f32x8) -> Box3 {
    let a = v.as_array();
    Box3 {
        min: Vec3A::new(a[0], a[1], a[2]),
        max: -Vec3A::new(a[4], a[5], a[6]),
    }
}

/// Half the surface area of a `[min, -max]` box (0 when empty), in `f64`: the products of
/// extents beyond about 1e19 overflow `f32`, and one far vertex would price every split of
/// the nodes above it at infinity.
#[inline(always)]
fn half_area8(v: f32x8) -> f64 {
    let a = v.as_array();
    // max - min = -(-max + min)
    let e = (-(Vec3A::new(a[4], a[5], a[6]) + Vec3A::new(a[0], a[1], a[2]))).max(Vec3A::ZERO);
    let (x, y, z) = (f64::from(e.x), f64::from(e.y), f64::from(e.z));
    x * y + y * z + z * x
}

impl Bins {
    fn clear(&mut self, k: usize) {
        for a in 0..3 {
            self.b[a][..k].fill(EMPTY_BIN);
        }
    }

    fn merge_from(&mut self, o: &Bins, k: usize) {
        for a in 0..3 {
            for i in 0..k {
                self.b[a][i] = merge_bin(self.b[a][i], o.b[a][i]);
            }
        }
    }

    fn merge(mut self, o: &Bins, k: usize) -> Bins {
        self.merge_from(o, k);
        self
    }

    /// Adds `r` (its bins on each axis given by `map`, noted in `r.bins`); returns its doubled
    /// centroid.
    #[inline(always)]
    fn add(&mut self, r: &mut PrimRef, map: &BinMap) -> Vec3A {
        let p = r.packed().fast_max(KEEP_COUNT);
        let c2 = r.c2();
        let [ix, iy, iz] = map.index(c2);
        r.set_bins(ix as u32 | (iy as u32) << 8 | (iz as u32) << 16);
        let grow = |bin: f32x8| {
            let bumped: f32x8 = bytemuck::cast(bytemuck::cast::<_, i32x8>(bin) + COUNT_ONE);
            bumped.fast_min(p)
        };
        self.b[0][ix] = grow(self.b[0][ix]);
        self.b[1][iy] = grow(self.b[1][iy]);
        self.b[2][iz] = grow(self.b[2][iz]);
        c2
    }
}

/// Maps doubled centroids to bin indices `0 .. k` on each axis (an axis with scale 0 is not
/// binned: everything lands in its bin 0).
#[derive(Clone, Copy)]
struct BinMap {
    origin: Vec3A,
    scale: Vec3A,
    /// `k - 1` as a float, the largest index.
    last: Vec3A,
    k: usize,
}

/// 1.5 * 2^23: adding it to a float in `[-0.5, 2^22)` leaves `2^22` plus the nearest integer
/// in the mantissa.
const ROUNDING_MAGIC: f32 = 12_582_912.0;

impl BinMap {
    /// The map spreading `cb` over `k` bins on each usable axis (all, or only the widest).
    fn new(cb: &Box3, k: usize, all_axes: bool) -> BinMap {
        let ext = cb.max - cb.min;
        let widest = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        let s = Vec3A::splat(k as f32) / ext;
        let mut ok = ext.cmpgt(Vec3A::ZERO) & s.is_finite_mask();
        if !all_axes {
            ok &= BVec3A::new(widest == 0, widest == 1, widest == 2);
        }
        let scale = Vec3A::select(ok, s, Vec3A::ZERO);
        BinMap {
            origin: cb.min,
            scale,
            last: Vec3A::splat((k - 1) as f32),
            k,
        }
    }

    fn usable(&self, axis: usize) -> bool {
        self.scale[axis] > 0.0
    }

    fn any_usable(&self) -> bool {
        self.scale.cmpgt(Vec3A::ZERO).any()
    }

    /// Bin indices of a doubled centroid on each axis: clamped to `[0, k - 1]` (so that the map
    /// is monotone everywhere, also for centroids outside a predicted range), then rounded
    /// (`x - 0.5` to nearest, i.e. down) through the mantissa, branch-free.
    #[inline(always)]
    fn index(&self, c2: Vec3A) -> [usize; 3] {
        // `max` first: it turns a NaN (0 times infinity on an unused axis) into 0.
        let x = ((c2 - self.origin) * self.scale)
            .max(Vec3A::ZERO)
            .min(self.last)
            + Vec3A::splat(ROUNDING_MAGIC - 0.5);
        x.to_array()
            .map(|f| ((f.to_bits() & 0x7f_ffff).wrapping_sub(1 << 22) as usize) & (MAX_BINS - 1))
    }
}

/// What a node knows about its primitives on entry.
#[derive(Clone, Copy)]
struct Info {
    bounds: Box3,
    /// Exact (doubled) centroid bounds.
    cbounds: Box3,
    /// When set, the node's bins (in the stack) already hold its primitives, binned with this
    /// map, and each primitive's `bins` field says where.
    map: Option<BinMap>,
}

/// A task's bins: two per tree level below the task's root (the pair of children a split
/// fills), so that a right child's bins wait intact while its left sibling's subtree is built.
struct Stack(Option<Vec<[Bins; 2]>>);

/// How many spare stacks a thread keeps: one per build task it may have in progress at once
/// (a task waiting in `join` while the thread runs a stolen one).
const SPARES: usize = 8;

thread_local! {
    /// Each thread's spare stacks, handed from one build task to the next so that tasks
    /// allocate none once every thread has its own.
    static SPARE_STACKS: std::cell::RefCell<[Option<Vec<[Bins; 2]>>; SPARES]> =
        const { std::cell::RefCell::new([const { None }; SPARES]) };
}

/// Levels a stack is reserved for: the deepest SAH split's, so that a warm stack never
/// reallocates.
const STACK_LEVELS: usize = SAH_DEPTH_LIMIT as usize + 2 + DUAL_SPARE;

/// Gives the calling thread all its [`SPARES`] stacks now (reserved, not written: about 1.3 MB
/// of address space each, of which a build touches the levels it reaches), so that no build
/// task it runs later allocates one.
pub(super) fn warm_thread_spares() {
    SPARE_STACKS.with_borrow_mut(|s| {
        for slot in s.iter_mut().filter(|s| s.is_none()) {
            *slot = Some(Vec::with_capacity(STACK_LEVELS));
        }
    });
}

impl Stack {
    fn take() -> Self {
        let spare = SPARE_STACKS.with_borrow_mut(|s| s.iter_mut().find_map(Option::take));
        Self(Some(
            spare.unwrap_or_else(|| Vec::with_capacity(STACK_LEVELS)),
        ))
    }

    /// The levels `level` and `level + 1` (growing the stack as needed).
    fn pair(&mut self, level: usize) -> (&mut [Bins; 2], &mut [Bins; 2]) {
        let (a, b, _) = self.levels(level, 0);
        (a, b)
    }

    /// The levels `level` and `level + 1`, and the `spare` levels after them (growing the
    /// stack as needed).
    fn levels(
        &mut self,
        level: usize,
        spare: usize,
    ) -> (&mut [Bins; 2], &mut [Bins; 2], &mut [[Bins; 2]]) {
        let v = self.0.get_or_insert_with(Vec::new);
        while v.len() < level + 2 + spare {
            v.push([EMPTY_BINS; 2]);
        }
        let (a, b) = v[level..level + 2 + spare].split_at_mut(1);
        let (b, c) = b.split_at_mut(1);
        (&mut a[0], &mut b[0], c)
    }
}

impl Drop for Stack {
    fn drop(&mut self) {
        let stack = self.0.take();
        SPARE_STACKS.with_borrow_mut(|s| {
            if let Some(slot) = s.iter_mut().find(|b| b.is_none()) {
                *slot = stack;
            }
        });
    }
}

/// The number of primitives in each subset of a small node, by bit set.
const SUBSET_COUNTS: [f32; 1 << SMALL] = {
    let mut c = [0.0; 1 << SMALL];
    let mut m = 0;
    while m < c.len() {
        c[m] = (m as u32).count_ones() as f32;
        m += 1;
    }
    c
};

/// A small node's primitive boxes, the areas of all their subsets (by bit set), and the leaf
/// order of its primitives as [`Ctx::small_node`] finds it.
struct Subsets {
    prims: [f32x8; SMALL],
    areas: [f32; 1 << SMALL],
    /// Each subset's area times its primitive count: a cut's price is the sum of its two
    /// sides'.
    weighted: [f32; 1 << SMALL],
    order: [u8; SMALL],
    len: usize,
}

/// A split: `refs[..mid]` go left; both children's [`Info`], their bins filled in the stack's
/// next level when their maps are set.
struct Split {
    mid: usize,
    left: Info,
    right: Info,
}

impl Ctx<'_> {
    /// Bins for a node of `n` primitives: at most one per four primitives (and at least 4, or
    /// `n` if fewer): a small node's candidates cost more to price than they gain.
    #[inline]
    fn bins_for(&self, n: usize) -> usize {
        (n / 4).max(4).min(n).min(self.bins).max(2)
    }

    /// Builds the subtree over `refs`; its bins (if `info.map` is set) are `stack[level][side]`.
    /// Returns its root and the number of its descendants.
    ///
    /// A subtree built by one task (below `parallel_threshold`) packs its nodes at the start of
    /// its slots (the right child's subtree right after the left's) instead of in the halves
    /// reserved for each: fewer memory pages touched, and the final compaction reads them in
    /// order.
    #[allow(clippy::too_many_arguments)]
    fn node(
        &self,
        refs: &mut [PrimRef],
        info: Info,
        out: Slots<'_>,
        depth: u32,
        stack: &mut Stack,
        level: usize,
        side: usize,
    ) -> (Node, u32) {
        let n = refs.len();
        if n <= SMALL && depth < SAH_DEPTH_LIMIT {
            return self.small_node(refs, info.bounds, out);
        }
        let bounds = info.bounds.to_aabb();
        if n == 1 {
            return (Node::leaf(bounds, out.prim_offset, 1), 0);
        }
        let split = if depth < SAH_DEPTH_LIMIT {
            self.split(refs, &info, depth, stack, level, side)
        } else {
            None
        };
        let split = match split {
            Some(sp) => sp,
            None if n <= self.max_leaf_size => {
                in_id_order(refs);
                return (Node::leaf(bounds, out.prim_offset, n as u32), 0);
            }
            None => {
                in_id_order(refs);
                let h = halve(refs, self.parallel_threshold);
                let info = |rb: RangeBounds| Info {
                    bounds: rb.bounds,
                    cbounds: rb.cbounds,
                    map: None,
                };
                Split {
                    mid: h.mid,
                    left: info(h.left),
                    right: info(h.right),
                }
            }
        };
        let mid = split.mid;
        debug_assert!(mid > 0 && mid < n);
        let (pair, rest) = out.desc.split_at_mut(2);
        let (lrefs, rrefs) = refs.split_at_mut(mid);
        let lbase = out.desc_base + 2;
        let rprim = out.prim_offset + mid as u32;
        let (l, r) = if n >= self.parallel_threshold && self.threads > 1 {
            // The right child becomes a task of its own, with its bins in a stack of its own.
            // (Its stack is taken when the task starts, so that a thread holds one stack per
            // task it has in progress, not one per pending sibling.)
            let (ldesc, rdesc) = rest.split_at_mut(2 * mid - 2);
            let left = Slots {
                prim_offset: out.prim_offset,
                desc: ldesc,
                desc_base: lbase,
            };
            let right = Slots {
                prim_offset: rprim,
                desc_base: lbase + 2 * mid as u32 - 2,
                desc: rdesc,
            };
            let rbins = split.right.map.map(|_| stack.pair(level).1[1]);
            let (l, r) = rayon::join(
                || self.subtree(lrefs, split.left, left, depth + 1, stack, level + 1, 0),
                || {
                    let mut rs = Stack::take();
                    if let Some(b) = rbins {
                        rs.pair(0).0[0] = b;
                    }
                    self.subtree(rrefs, split.right, right, depth + 1, &mut rs, 0, 0)
                },
            );
            self.splits
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push([out.desc_base, l.1, r.1]);
            (l, r)
        } else {
            let left = Slots {
                prim_offset: out.prim_offset,
                desc: &mut *rest,
                desc_base: lbase,
            };
            let l = self.node(lrefs, split.left, left, depth + 1, stack, level + 1, 0);
            let right = Slots {
                prim_offset: rprim,
                desc_base: lbase + l.1,
                desc: &mut rest[l.1 as usize..],
            };
            let r = self.node(rrefs, split.right, right, depth + 1, stack, level + 1, 1);
            (l, r)
        };
        pair[0] = l.0;
        pair[1] = r.0;
        (Node::interior(bounds, out.desc_base), 2 + l.1 + r.1)
    }

    /// [`Ctx::node`] for a child of a node split into two tasks. A subtree below
    /// `parallel_threshold`, which one task builds alone, goes into the calling thread's region
    /// when that has room, right after the region's last subtree, instead of into the start of
    /// its own reserved slots: a parallel build then writes its nodes densely, in few pages
    /// (huge ones where the system gives them), where its reserved slots would leave a gap
    /// after every such subtree.
    #[allow(clippy::too_many_arguments)]
    fn subtree(
        &self,
        refs: &mut [PrimRef],
        info: Info,
        out: Slots<'_>,
        depth: u32,
        stack: &mut Stack,
        level: usize,
        side: usize,
    ) -> (Node, u32) {
        let n = refs.len();
        if n < self.parallel_threshold
            && let Some(region) =
                rayon::current_thread_index().and_then(|t| self.regions.get(t)?.as_ref())
            // Only this thread takes its region, and never while it builds in it (a subtree
            // below the threshold runs no parallel step).
            && let Ok(mut region) = region.try_lock()
            && region.nodes.len() - region.used >= 2 * n - 2
        {
            let at = region.used;
            let into = Slots {
                prim_offset: out.prim_offset,
                desc_base: region.base + at as u32,
                desc: &mut region.nodes[at..at + 2 * n - 2],
            };
            let built = self.node(refs, info, into, depth, stack, level, side);
            region.used += built.1 as usize;
            return built;
        }
        self.node(refs, info, out, depth, stack, level, side)
    }

    /// Finds the cheapest split of the node's bins (binning first if the node was not binned
    /// by its parent), partitions `refs` and bins the children on the way; `None` to make a
    /// leaf (or cut in the middle if there are too many primitives for one).
    fn split(
        &self,
        refs: &mut [PrimRef],
        info: &Info,
        depth: u32,
        stack: &mut Stack,
        level: usize,
        side: usize,
    ) -> Option<Split> {
        let n = refs.len();
        // Large nodes bin into two sets per side (see `partition_bin_dual`), kept in the two
        // stack levels after the children's: those are free until a child splits.
        let dual = n >= DUAL_MIN;
        let (cur, next, spare) = stack.levels(level, if dual { DUAL_SPARE } else { 0 });
        let bins = &mut cur[side];
        let map = match info.map {
            Some(m) if m.any_usable() => m,
            // Not binned yet, or binned with a predicted map that was empty on every axis.
            _ => {
                let map = BinMap::new(&info.cbounds, self.bins_for(n), self.all_axes);
                if !map.any_usable() {
                    return None;
                }
                self.bin(refs, &map, bins);
                map
            }
        };
        let k = map.k;

        // Cost of splitting after each bin on each axis: right-to-left areas times counts,
        // then left to right `A_L N_L + A_R N_R`. A side with no primitive prices its candidate
        // at infinity; empty bins leave both sides unchanged (ties keep the first candidate).
        let mut best = (f64::INFINITY, 0usize, 0usize);
        let mut right_cost = [0f64; MAX_BINS];
        for axis in (0..3).filter(|&a| map.usable(a)) {
            let bx = &bins.b[axis][..k];
            let mut acc = EMPTY8;
            let mut count = 0u32;
            for i in (1..k).rev() {
                acc = acc.fast_min(bx[i]);
                count += count_of(bx[i]);
                let c = half_area8(acc) * f64::from(count);
                right_cost[i - 1] = if count == 0 { f64::INFINITY } else { c };
            }
            let mut acc = EMPTY8;
            let mut count = 0u32;
            let (mut best_cost, mut best_bin) = (f64::INFINITY, 0);
            for i in 0..k - 1 {
                acc = acc.fast_min(bx[i]);
                count += count_of(bx[i]);
                let c = half_area8(acc) * f64::from(count) + right_cost[i];
                let c = if count == 0 { f64::INFINITY } else { c };
                // Branch-free: which candidate wins is unpredictable.
                let better = c < best_cost;
                best_cost = if better { c } else { best_cost };
                best_bin = if better { i } else { best_bin };
            }
            if best_cost < best.0 {
                best = (best_cost, axis, best_bin);
            }
        }
        let (cost, axis, bin) = best;
        if !cost.is_finite() {
            return None;
        }
        let area = info.bounds.half_area_f64();
        let split_cost =
            f64::from(self.traversal_cost) * area + f64::from(self.intersection_cost) * cost;
        let leaf_cost = f64::from(self.intersection_cost) * area * n as f64;
        if split_cost >= leaf_cost && n <= self.max_leaf_size {
            return None;
        }

        // The children: boxes and counts from the bins, predicted maps, then the partition
        // bins them.
        let bx = &bins.b[axis][..k];
        let union = |b: &[f32x8]| unpack(b.iter().fold(EMPTY8, |acc, b| acc.fast_min(*b)));
        let (lb, rb) = (union(&bx[..=bin]), union(&bx[bin + 1..]));
        let nl = bx[..=bin].iter().map(|&b| count_of(b)).sum::<u32>() as usize;
        let nr = n - nl;
        // The centroid boundary between the two sides on the split axis (its bins are noted in
        // each primitive, so the partition does not depend on rounding here).
        let cut = map.origin[axis] + (bin + 1) as f32 / map.scale[axis];
        let child_map = |bounds: &Box3, count: usize, left: bool| {
            // Children at the depth limit are never split by SAH, and small ones are swept
            // instead of binned.
            if count <= SMALL || depth + 1 >= SAH_DEPTH_LIMIT {
                return None;
            }
            let mut cb = Box3 {
                min: info.cbounds.min.max(bounds.min * 2.0),
                max: info.cbounds.max.min(bounds.max * 2.0),
            };
            if left {
                cb.max[axis] = cb.max[axis].min(cut);
            } else {
                cb.min[axis] = cb.min[axis].max(cut);
            }
            Some(BinMap::new(&cb, self.bins_for(count), self.all_axes))
        };
        let lmap = child_map(&lb, nl, true);
        let rmap = child_map(&rb, nr, false);
        if let Some(m) = &lmap {
            next[0].clear(m.k);
        }
        if let Some(m) = &rmap {
            next[1].clear(m.k);
        }
        let [lbins, rbins] = next;
        let shift = 8 * axis as u32;
        let bin = bin as u32;
        let goes_left = |r: &PrimRef| (r.bins() >> shift) & 0xff <= bin;
        // The top levels, whose subtrees are still fewer than the threads, partition in
        // parallel blocks, so that every thread has work before there are subtrees for all.
        let threads = self.threads;
        let (mid, lcb, rcb) = if threads > 1
            && (depth as usize) < usize::BITS as usize - 1
            && (1usize << depth) < threads
            && n >= self.parallel_threshold.saturating_mul(8)
        {
            let blocks = (threads >> depth).max(2);
            let (lmap, rmap) = (
                *lmap.as_ref().unwrap_or(&NO_MAP),
                *rmap.as_ref().unwrap_or(&NO_MAP),
            );
            let p = par_partition_bin(
                refs,
                &goes_left,
                (&lmap, &rmap),
                n.div_ceil(blocks),
                self.parallel_threshold.saturating_mul(8),
            );
            *lbins = p.l;
            *rbins = p.r;
            (p.mid, p.lcb, p.rcb)
        } else {
            match (&lmap, &rmap) {
                (Some(lm), Some(rm)) if dual => {
                    let [lp, rp] = spare else {
                        unreachable!("two spare levels")
                    };
                    let r = partition_bin_dual(refs, goes_left, (lm, lp), (rm, rp));
                    lbins.clear(lm.k);
                    rbins.clear(rm.k);
                    for b in &*lp {
                        lbins.merge_from(b, lm.k);
                    }
                    for b in &*rp {
                        rbins.merge_from(b, rm.k);
                    }
                    r
                }
                (Some(lm), Some(rm)) => {
                    partition_bin::<true, true>(refs, goes_left, (lm, lbins), (rm, rbins))
                }
                (Some(lm), None) => {
                    partition_bin::<true, false>(refs, goes_left, (lm, lbins), (&NO_MAP, rbins))
                }
                (None, Some(rm)) => {
                    partition_bin::<false, true>(refs, goes_left, (&NO_MAP, lbins), (rm, rbins))
                }
                (None, None) => partition_bin::<false, false>(
                    refs,
                    goes_left,
                    (&NO_MAP, lbins),
                    (&NO_MAP, rbins),
                ),
            }
        };
        debug_assert_eq!(mid, nl);
        Some(Split {
            mid,
            left: Info {
                bounds: lb,
                cbounds: lcb,
                map: lmap,
            },
            right: Info {
                bounds: rb,
                cbounds: rcb,
                map: rmap,
            },
        })
    }

    /// Builds the subtree of a node of at most [`SMALL`] primitives (bounded by `bounds`),
    /// packed at the start of its slots, by a lean recursion of its own: every way to cut such
    /// a node in two is priced (3 for 3 primitives, 7 for 4, 15 for 5, 31 for 6), which costs less than
    /// clearing, filling and pricing bins, and finds the best split there is. The areas of all
    /// subsets of the node's primitives are made once (each box the union of two from tables
    /// over the first three and the last two primitives) and serve every node below it;
    /// the references are put in leaf order at the end. Returns the subtree's root and the
    /// number of its descendants.
    fn small_node(&self, refs: &mut [PrimRef], bounds: Box3, out: Slots<'_>) -> (Node, u32) {
        let n = refs.len();
        debug_assert!((1..=SMALL).contains(&n));
        if n == 1 {
            return (Node::leaf(bounds.to_aabb(), out.prim_offset, 1), 0);
        }
        // The primitives taken in the order of their indices (see `in_id_order`): a
        // permutation of the few, sorted by insertion on their indices alone.
        let mut perm = [0u8; SMALL];
        let mut ids = [0u32; SMALL];
        for (i, r) in refs.iter().enumerate() {
            let id = r.id();
            let mut j = i;
            while j > 0 && ids[j - 1] > id {
                ids[j] = ids[j - 1];
                perm[j] = perm[j - 1];
                j -= 1;
            }
            ids[j] = id;
            perm[j] = i as u8;
        }
        let mut t = Subsets {
            prims: [EMPTY8; SMALL],
            areas: [0.0; 1 << SMALL],
            weighted: [0.0; 1 << SMALL],
            order: [0; SMALL],
            len: 0,
        };
        for (b, &i) in t.prims.iter_mut().zip(&perm[..n]) {
            *b = refs[i as usize].packed();
        }
        // The boxes of the subsets of the first three and of the last two primitives; a
        // subset's box is the union of one of each.
        let mut lo = [EMPTY8; 8];
        for m in 1..1usize << n.min(3) {
            lo[m] = lo[m & (m - 1)].fast_min(t.prims[m.trailing_zeros() as usize]);
        }
        let mut hi = [EMPTY8; 1 << (SMALL - 3)];
        for m in 1..1usize << n.saturating_sub(3) {
            hi[m] = hi[m & (m - 1)].fast_min(t.prims[3 + m.trailing_zeros() as usize]);
        }
        // Eight subsets at a time: the table over the first three, transposed, each coordinate
        // of its eight boxes in one vector, against one box of the last primitives.
        let lo_t: [f32x8; 6] = std::array::from_fn(|c| {
            let c = if c < 3 { c } else { c + 1 };
            f32x8::new(std::array::from_fn(|m| lo[m].as_array()[c]))
        });
        let zero = f32x8::splat(0.0);
        for (((h, areas), weighted), counts) in hi[..1 << n.saturating_sub(3)]
            .iter()
            .zip(t.areas.chunks_exact_mut(8))
            .zip(t.weighted.chunks_exact_mut(8))
            .zip(SUBSET_COUNTS.chunks_exact(8))
        {
            let h = h.as_array();
            let side = |c: usize| {
                let min = lo_t[c].fast_min(f32x8::splat(h[c]));
                let nmax = lo_t[c + 3].fast_min(f32x8::splat(h[c + 4]));
                // max - min = -(-max + min), as `half_area8` has it
                (-(nmax + min)).fast_max(zero)
            };
            let (x, y, z) = (side(0), side(1), side(2));
            let a = x * y + y * z + z * x;
            areas.copy_from_slice(&a.to_array());
            weighted.copy_from_slice(&(a * f32x8::new(counts.try_into().unwrap())).to_array());
        }
        let all = (1u32 << n) - 1;
        t.areas[all as usize] = bounds.half_area();
        t.weighted[all as usize] = t.areas[all as usize] * n as f32;
        let root = self.small_subtree(&mut t, all, bounds.to_aabb(), out);
        let mut old = [PrimRef::zeroed(); SMALL];
        old[..n].copy_from_slice(refs);
        for (r, &i) in refs.iter_mut().zip(&t.order[..n]) {
            *r = old[perm[i as usize] as usize];
        }
        root
    }

    /// The subtree of [`Ctx::small_node`] over the primitives in the bit set `set`, bounded by
    /// `bounds`: its leaves' primitives are appended to `t.order`.
    fn small_subtree(
        &self,
        t: &mut Subsets,
        set: u32,
        bounds: crate::geom::Aabb,
        out: Slots<'_>,
    ) -> (Node, u32) {
        let n = set.count_ones();
        let leaf = |t: &mut Subsets| {
            let mut s = set;
            while s != 0 {
                t.order[t.len] = s.trailing_zeros() as u8;
                t.len += 1;
                s &= s - 1;
            }
            (Node::leaf(bounds, out.prim_offset, n), 0)
        };
        if n == 1 {
            return leaf(t);
        }
        // Left sides: the subsets of `set` without its highest primitive (which always goes
        // right, so that each way to cut is priced once), in increasing order.
        let rest = set & !(1 << (31 - set.leading_zeros()));
        let (best_cost, mut best) = if n >= 4 && set == (1 << n) - 1 {
            // The whole node: its cuts are priced eight at a time.
            best_cut_of_all(&t.weighted, n)
        } else {
            let (mut best_cost, mut best) = (f32::INFINITY, 0u32);
            let mut s = 0u32;
            loop {
                s = (s | !rest).wrapping_add(1) & rest;
                if s == 0 {
                    break;
                }
                let c = t.weighted[s as usize] + t.weighted[(set ^ s) as usize];
                if c < best_cost {
                    best_cost = c;
                    best = s;
                }
            }
            (best_cost, best)
        };
        let area = t.areas[set as usize];
        let split_cost = self.traversal_cost * area + self.intersection_cost * best_cost;
        let leaf_cost = self.intersection_cost * area * n as f32;
        if !best_cost.is_finite() || split_cost >= leaf_cost {
            if n as usize <= self.max_leaf_size {
                return leaf(t);
            }
            if !best_cost.is_finite() {
                // No split has a price (infinite areas): cut by count (the lowest half).
                best = 0;
                let mut s = set;
                for _ in 0..n / 2 {
                    best |= s & s.wrapping_neg();
                    s &= s - 1;
                }
            }
        }
        let (pair, rest) = out.desc.split_at_mut(2);
        let lbase = out.desc_base + 2;
        let union = |mut s: u32| {
            let mut b = EMPTY8;
            while s != 0 {
                b = b.fast_min(t.prims[s.trailing_zeros() as usize]);
                s &= s - 1;
            }
            unpack(b).to_aabb()
        };
        let (lbounds, rbounds) = (union(best), union(set ^ best));
        let l = self.small_subtree(
            t,
            best,
            lbounds,
            Slots {
                prim_offset: out.prim_offset,
                desc: &mut *rest,
                desc_base: lbase,
            },
        );
        let r = self.small_subtree(
            t,
            set ^ best,
            rbounds,
            Slots {
                prim_offset: out.prim_offset + best.count_ones(),
                desc: &mut rest[l.1 as usize..],
                desc_base: lbase + l.1,
            },
        );
        pair[0] = l.0;
        pair[1] = r.0;
        (Node::interior(bounds, out.desc_base), 2 + l.1 + r.1)
    }

    /// Bins `refs` with `map` into `bins` (in parallel chunks for large nodes).
    fn bin(&self, refs: &mut [PrimRef], map: &BinMap, bins: &mut Bins) {
        let k = map.k;
        if refs.len() >= self.parallel_threshold.saturating_mul(8) {
            *bins = refs
                .par_chunks_mut(self.parallel_threshold)
                .map(|c| {
                    // Two sets taken in turn, as in `partition_bin_dual`.
                    let mut b = [EMPTY_BINS; 2];
                    for (i, r) in c.iter_mut().enumerate() {
                        b[i & 1].add(r, map);
                    }
                    b[0].merge(&b[1], k)
                })
                .reduce(|| EMPTY_BINS, |a, b| a.merge(&b, k));
        } else {
            bins.clear(k);
            for r in refs {
                bins.add(r, map);
            }
        }
    }
}

/// The cheapest cut of a whole small node of `n` primitives (`4 <= n <= SMALL`), as the scalar
/// search in [`Ctx::small_subtree`] finds it (the first of the cheapest left sides `s`, taken in
/// increasing order without the highest primitive), from each subset's area times count:
/// the price of `s` is `weighted[s] + weighted[all - s]`, eight values of `s` at a time.
fn best_cut_of_all(weighted: &[f32; 1 << SMALL], n: u32) -> (f32, u32) {
    let all = (1usize << n) - 1;
    let chunks = (1usize << (n - 1)) / 8;
    // `s = 0` (no cut) is priced at infinity.
    let no_cut = f32x8::new([f32::INFINITY, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let mut costs = [EMPTY8; 1 << (SMALL - 4)];
    let mut least = EMPTY8;
    for (c, cost) in costs.iter_mut().enumerate().take(chunks) {
        let left: [f32; 8] = weighted[8 * c..8 * c + 8].try_into().unwrap();
        let mut right: [f32; 8] = weighted[all - 8 * c - 7..=all - 8 * c].try_into().unwrap();
        right.reverse();
        *cost = f32x8::new(left) + f32x8::new(right);
        if c == 0 {
            *cost += no_cut;
        }
        least = least.fast_min(*cost);
    }
    let best_cost = least.to_array().into_iter().fold(f32::INFINITY, f32::min);
    for (c, cost) in costs.iter().enumerate().take(chunks) {
        let hits = cost.simd_eq(f32x8::splat(best_cost)).to_bitmask();
        if hits != 0 {
            return (best_cost, (8 * c as u32) + hits.trailing_zeros());
        }
    }
    (f32::INFINITY, 0)
}

/// Partitions `refs` in place by `goes_left` (Hoare: each reference is classified once), and
/// bins each reference of a side that `BL` / `BR` say is binned into that side's bins with its
/// map, gathering that side's doubled centroid bounds (a side that is not binned never needs
/// them: it is small, or at the depth limit). Returns the left count and the two centroid
/// bounds (empty for a side not binned).
fn partition_bin<const BL: bool, const BR: bool>(
    refs: &mut [PrimRef],
    goes_left: impl Fn(&PrimRef) -> bool,
    left: (&BinMap, &mut Bins),
    right: (&BinMap, &mut Bins),
) -> (usize, Box3, Box3) {
    let (lmap, lbins) = left;
    let (rmap, rbins) = right;
    let (lmap, rmap) = (*lmap, *rmap);
    let mut lcb = Box3::EMPTY;
    let mut rcb = Box3::EMPTY;
    let (mut i, mut j) = (0, refs.len());
    loop {
        while i < j && goes_left(&refs[i]) {
            if BL {
                lcb.grow_point(lbins.add(&mut refs[i], &lmap));
            }
            i += 1;
        }
        while i < j && !goes_left(&refs[j - 1]) {
            if BR {
                rcb.grow_point(rbins.add(&mut refs[j - 1], &rmap));
            }
            j -= 1;
        }
        if i >= j {
            break;
        }
        refs.swap(i, j - 1);
    }
    (i, lcb, rcb)
}

/// Nodes of at least this many primitives partition with [`partition_bin_dual`].
const DUAL_MIN: usize = 1024;
/// The stack levels [`partition_bin_dual`] borrows.
const DUAL_SPARE: usize = 2;

/// [`partition_bin`] with both sides binned, each into two sets of bins taken in turn (by
/// position), merged by the caller: consecutive primitives, which tend to fall into the same
/// bins, then do not wait on each other's bin update (a store and a reload per bin).
fn partition_bin_dual(
    refs: &mut [PrimRef],
    goes_left: impl Fn(&PrimRef) -> bool,
    left: (&BinMap, &mut [Bins; 2]),
    right: (&BinMap, &mut [Bins; 2]),
) -> (usize, Box3, Box3) {
    let (lmap, lbins) = left;
    let (rmap, rbins) = right;
    let (lmap, rmap) = (*lmap, *rmap);
    for b in lbins.iter_mut() {
        b.clear(lmap.k);
    }
    for b in rbins.iter_mut() {
        b.clear(rmap.k);
    }
    let mut lcb = Box3::EMPTY;
    let mut rcb = Box3::EMPTY;
    let (mut i, mut j) = (0, refs.len());
    loop {
        while i < j && goes_left(&refs[i]) {
            lcb.grow_point(lbins[i & 1].add(&mut refs[i], &lmap));
            i += 1;
        }
        while i < j && !goes_left(&refs[j - 1]) {
            rcb.grow_point(rbins[j & 1].add(&mut refs[j - 1], &rmap));
            j -= 1;
        }
        if i >= j {
            break;
        }
        refs.swap(i, j - 1);
    }
    (i, lcb, rcb)
}

/// A block's partition: its left count, both sides' doubled centroid bounds and bins.
struct Part {
    mid: usize,
    lcb: Box3,
    rcb: Box3,
    l: Bins,
    r: Bins,
}

/// [`partition_bin`] in parallel: blocks of at most `block` references are partitioned (and
/// binned into bins of their own) as parallel tasks, then each pair of neighbouring blocks
/// `[L1 R1] [L2 R2]` is joined by swapping the shorter of `R1` and `L2` with the far end of
/// the other (the order within a side does not matter), and their bins merged. Swaps of at
/// least `par_swap` references are split into parallel chunks.
fn par_partition_bin(
    refs: &mut [PrimRef],
    goes_left: &(impl Fn(&PrimRef) -> bool + Sync),
    maps: (&BinMap, &BinMap),
    block: usize,
    par_swap: usize,
) -> Part {
    let n = refs.len();
    if n <= block.max(2) {
        // (A side that is not binned is binned with [`NO_MAP`], into bins nobody reads.)
        let (mut l, mut r) = ([EMPTY_BINS; 2], [EMPTY_BINS; 2]);
        let (mid, lcb, rcb) =
            partition_bin_dual(refs, goes_left, (maps.0, &mut l), (maps.1, &mut r));
        let (l, r) = (l[0].merge(&l[1], maps.0.k), r[0].merge(&r[1], maps.1.k));
        return Part {
            mid,
            lcb,
            rcb,
            l,
            r,
        };
    }
    let h = n / 2;
    let (a, b) = refs.split_at_mut(h);
    let (pa, pb) = rayon::join(
        || par_partition_bin(a, goes_left, maps, block, par_swap),
        || par_partition_bin(b, goes_left, maps, block, par_swap),
    );
    // `a` is `[La Ra]`, `b` is `[Lb Rb]`: swap the shorter of `Ra` and `Lb` with the end of the
    // other next to it, giving `[La Lb' | Ra' Rb]`.
    let m = (h - pa.mid).min(pb.mid);
    let xs = &mut a[pa.mid..pa.mid + m];
    let ys = &mut b[pb.mid - m..pb.mid];
    if m >= par_swap.max(1) {
        let c = m.div_ceil(rayon::current_num_threads().max(1) * 2).max(1);
        xs.par_chunks_mut(c)
            .zip(ys.par_chunks_mut(c))
            .for_each(|(x, y)| x.swap_with_slice(y));
    } else {
        xs.swap_with_slice(ys);
    }
    Part {
        mid: pa.mid + pb.mid,
        lcb: pa.lcb.union(pb.lcb),
        rcb: pa.rcb.union(pb.rcb),
        l: pa.l.merge(&pb.l, maps.0.k),
        r: pa.r.merge(&pb.r, maps.1.k),
    }
}

/// The map of a side that is not binned: everything into bin 0.
const NO_MAP: BinMap = BinMap {
    origin: Vec3A::ZERO,
    scale: Vec3A::ZERO,
    last: Vec3A::ZERO,
    k: 1,
};

/// Slots for the threads' regions of a parallel build over `n` primitives (0 when it makes no
/// task): one and a half times the most nodes a tree can have, split evenly among the threads
/// (at most [`MAX_REGIONS`] of them), so that each
/// thread has room for half as much again as an even share of the most; a subtree that does not
/// fit goes into its reserved slots.
pub(crate) fn regions_len(n: usize, p: &BuildParams, threads: usize) -> usize {
    if threads <= 1 || n < 2 * p.parallel_threshold.max(1) {
        return 0;
    }
    let most = 2 * n - 1;
    let threads = threads.min(MAX_REGIONS);
    let len = threads * (most * 3 / (2 * threads)).max(2 * p.parallel_threshold);
    // Slot indices are `u32`.
    if most + len > u32::MAX as usize {
        return 0;
    }
    len
}
