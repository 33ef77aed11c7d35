//! BVH construction. Builders see only primitive boxes (and their centroids), never triangles.
//!
//! Every builder writes the same layout: a node's two children are adjacent and come after it,
//! and every subtree owns a contiguous range of nodes and of primitive slots. While building, a
//! subtree over `n` primitives reserves `2n - 2` node slots for its descendants (the most a
//! binary tree with `n` leaves can need), so parallel subtrees write disjoint slices with no
//! locking; the unused slots are squeezed out at the end without changing the order.

mod binned;
mod median;
mod sweep;

use super::{Bvh, MAX_DEPTH, Node};
use crate::geom::Aabb;
use glam::Vec3A;
use rayon::prelude::*;

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

/// A primitive as builders see it: its box, its id, and scratch room for the binned builder
/// (the bin of its centroid on each axis, one byte each), in 32 bytes.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub(crate) struct PrimRef {
    pub min: [f32; 3],
    pub id: u32,
    pub max: [f32; 3],
    pub bins: u32,
}

impl PrimRef {
    fn new(b: &Aabb, id: u32) -> Self {
        let b = b.sanitized();
        Self {
            min: b.min.into(),
            id,
            max: b.max.into(),
            bins: 0,
        }
    }

    #[inline(always)]
    pub fn lo(&self) -> Vec3A {
        Vec3A::from(self.min)
    }

    #[inline(always)]
    pub fn hi(&self) -> Vec3A {
        Vec3A::from(self.max)
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
    pub fn add_centroid(&mut self, r: &PrimRef) {
        self.cbounds.grow_point(r.c2());
    }

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
        if refs.len() >= 8 * parallel_threshold {
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

/// A split strategy over references kept in one array (binned SAH, median).
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

impl Bvh {
    /// Builds a BVH over primitives given by their boxes; primitive `i` has box `boxes[i]`.
    #[must_use]
    pub fn build(boxes: &[Aabb], params: &BuildParams) -> Bvh {
        let mut refs: Vec<PrimRef> = if boxes.len() >= 8 * params.parallel_threshold {
            boxes
                .par_iter()
                .enumerate()
                .map(|(i, b)| PrimRef::new(b, i as u32))
                .collect()
        } else {
            boxes
                .iter()
                .enumerate()
                .map(|(i, b)| PrimRef::new(b, i as u32))
                .collect()
        };
        if refs.is_empty() {
            return Bvh::empty(params.max_leaf_size);
        }
        let mut slots = vec![Node::default(); 2 * refs.len() - 1];
        let (root, desc) = slots.split_at_mut(1);
        match params.method {
            Method::Binned => {
                root[0] = build_range(&binned::Binned::new(params), params, &mut refs, desc);
            }
            Method::Median => {
                let m = median::Median(params.max_leaf_size as usize);
                root[0] = build_range(&m, params, &mut refs, desc);
            }
            Method::Sweep => {
                root[0] = sweep::build(params, &mut refs, desc);
            }
        }
        let prim_indices = refs.iter().map(|r| r.id).collect();
        Bvh {
            nodes: compact(slots),
            prim_indices,
            max_leaf_size: params.max_leaf_size,
        }
    }
}

/// Builds the whole tree over `refs` with one splitter: writes the root's descendants into
/// `desc` (global indices from 1) and returns the root.
fn build_range<S: Splitter>(
    splitter: &S,
    params: &BuildParams,
    refs: &mut [PrimRef],
    desc: &mut [Node],
) -> Node {
    let rb = RangeBounds::of(refs, params.parallel_threshold);
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

/// Removes the slots no node was written to, keeping the order, and renumbers child links.
fn compact(mut slots: Vec<Node>) -> Vec<Node> {
    // The slots of a leaf's unused descendants were never written: they still hold the
    // default node, whose count is 0. Mark them by walking the tree from the root.
    let mut used = vec![false; slots.len()];
    let mut stack = vec![0u32];
    while let Some(i) = stack.pop() {
        used[i as usize] = true;
        let n = slots[i as usize];
        if !n.is_leaf() {
            stack.push(n.first);
            stack.push(n.first + 1);
        }
    }
    let mut new_index = vec![0u32; slots.len()];
    let mut next = 0u32;
    for (i, &u) in used.iter().enumerate() {
        new_index[i] = next;
        next += u as u32;
    }
    let mut w = 0;
    for i in 0..slots.len() {
        if used[i] {
            let mut n = slots[i];
            if !n.is_leaf() {
                n.first = new_index[n.first as usize];
            }
            slots[w] = n;
            w += 1;
        }
    }
    slots.truncate(w);
    slots.shrink_to_fit();
    slots
}
