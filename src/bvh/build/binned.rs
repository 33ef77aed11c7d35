//! Binned SAH (Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies", 2007).

use super::{BuildParams, MAX_BINS, PrimRef, RangeBounds, Split, Splitter};
use crate::bvh::build::Box3;
use glam::Vec3A;
use rayon::prelude::*;

pub(crate) struct Binned {
    bins: usize,
    all_axes: bool,
    traversal_cost: f32,
    intersection_cost: f32,
    max_leaf_size: usize,
    parallel_threshold: usize,
}

impl Binned {
    pub fn new(p: &BuildParams) -> Self {
        Self {
            bins: p.bins.clamp(2, MAX_BINS),
            all_axes: p.all_axes,
            traversal_cost: p.traversal_cost,
            intersection_cost: p.intersection_cost,
            max_leaf_size: p.max_leaf_size.max(1) as usize,
            parallel_threshold: p.parallel_threshold.max(1),
        }
    }
}

/// One bin: the box and count of the primitives whose centroid falls in it.
#[derive(Clone, Copy)]
pub(crate) struct Bin {
    b: Box3,
    count: u32,
}

const EMPTY_BIN: Bin = Bin {
    b: Box3::EMPTY,
    count: 0,
};

/// Bins on the three axes; only the first `k` of each axis are in use.
pub(crate) type Bins = [[Bin; MAX_BINS]; 3];

/// Maps doubled centroids to bin indices `0 .. bins` on each axis.
#[derive(Clone, Copy)]
struct BinMap {
    origin: Vec3A,
    scale: Vec3A,
    last: u32,
}

/// 1.5 * 2^23: adding it to a float in `[-0.5, 2^22)` leaves `2^22` plus the nearest integer
/// in the mantissa.
const ROUNDING_MAGIC: f32 = 12_582_912.0;

impl BinMap {
    /// Bin indices of a doubled centroid on each axis. Rounding `x - 0.5` to the nearest integer
    /// through the mantissa is monotone and branch-free (unlike a saturating float-to-int cast);
    /// any monotone map gives valid bins, and partitioning reads back the same indices.
    #[inline(always)]
    fn index(&self, c2: Vec3A) -> [usize; 3] {
        let x = (c2 - self.origin) * self.scale + Vec3A::splat(ROUNDING_MAGIC - 0.5);
        x.to_array().map(|f| {
            let i = (f.to_bits() & 0x7f_ffff).wrapping_sub(1 << 22);
            (i.min(self.last) as usize) & (MAX_BINS - 1)
        })
    }
}

/// Adds `refs` to `bins` and notes each reference's bins in it.
fn bin_refs(refs: &mut [PrimRef], map: &BinMap, bins: &mut Bins) {
    let [bx, by, bz] = bins;
    for r in refs {
        let (lo, hi) = (r.lo(), r.hi());
        let [ix, iy, iz] = map.index(lo + hi);
        r.bins = ix as u32 | (iy as u32) << 8 | (iz as u32) << 16;
        for b in [&mut bx[ix], &mut by[iy], &mut bz[iz]] {
            b.b.grow(lo, hi);
            b.count += 1;
        }
    }
}

const EMPTY_BINS: Bins = [[EMPTY_BIN; MAX_BINS]; 3];

fn merge_bins(mut a: Bins, b: Bins, k: usize) -> Bins {
    for (xa, xb) in a.iter_mut().zip(b.iter()) {
        for (x, y) in xa[..k].iter_mut().zip(&xb[..k]) {
            x.b = x.b.union(y.b);
            x.count += y.count;
        }
    }
    a
}

/// How many spare bin sets a thread keeps: one per build task it may have in progress at once
/// (a task waiting in `join` while the thread runs a stolen one).
const SPARES: usize = 8;

thread_local! {
    /// Each thread's spare bins, handed from one build task to the next so that tasks allocate
    /// none once every thread has its sets.
    static SPARE_BINS: std::cell::RefCell<[Option<Box<Bins>>; SPARES]> =
        const { std::cell::RefCell::new([const { None }; SPARES]) };
}

/// A task's bins: taken from the thread's spares on creation, returned to them on drop.
pub(crate) struct BinsScratch(Option<Box<Bins>>);

impl BinsScratch {
    fn take() -> Self {
        let spare = SPARE_BINS.with_borrow_mut(|s| s.iter_mut().find_map(Option::take));
        Self(Some(spare.unwrap_or_else(|| Box::new(EMPTY_BINS))))
    }

    fn bins(&mut self) -> &mut Bins {
        self.0.get_or_insert_with(|| Box::new(EMPTY_BINS))
    }
}

impl Drop for BinsScratch {
    fn drop(&mut self) {
        let bins = self.0.take();
        SPARE_BINS.with_borrow_mut(|s| {
            if let Some(slot) = s.iter_mut().find(|b| b.is_none()) {
                *slot = bins;
            }
        });
    }
}

impl Splitter for Binned {
    type Scratch = BinsScratch;

    fn scratch(&self) -> BinsScratch {
        BinsScratch::take()
    }

    fn split(
        &self,
        refs: &mut [PrimRef],
        rb: &RangeBounds,
        scratch: &mut BinsScratch,
    ) -> Option<Split> {
        let bins = scratch.bins();
        let n = refs.len();
        // Small nodes get one bin per primitive at most: more bins could not separate more
        // centroids on average, and the per-node cost of sweeping empty bins would dominate.
        let k = self.bins.min(n.max(2));
        let origin = rb.cbounds.min;
        let ext = rb.cbounds.max - origin;
        let widest = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        let usable = |a: usize| {
            ext[a] > 0.0 && (k as f32 / ext[a]).is_finite() && (self.all_axes || a == widest)
        };
        if !(0..3).any(usable) {
            return None;
        }
        let mut scale = Vec3A::ZERO;
        for a in 0..3 {
            if usable(a) {
                scale[a] = k as f32 / ext[a];
            }
        }
        let map = BinMap {
            origin,
            scale,
            last: k as u32 - 1,
        };

        if n >= self.parallel_threshold.saturating_mul(8) {
            // Large nodes: bin chunks in parallel into bins on each task's stack.
            *bins = refs
                .par_chunks_mut(self.parallel_threshold)
                .map(|c| {
                    let mut b = EMPTY_BINS;
                    bin_refs(c, &map, &mut b);
                    b
                })
                .reduce(|| EMPTY_BINS, |a, b| merge_bins(a, b, k));
        } else {
            for axis in bins.iter_mut() {
                axis[..k].fill(EMPTY_BIN);
            }
            bin_refs(refs, &map, bins);
        }

        // Compute costs for splitting after each bin: right-to-left areas and counts first,
        // then a left-to-right sweep evaluates `A_L N_L + A_R N_R`. Empty bins change neither
        // side, so their candidates repeat the previous one and are skipped.
        let mut best = (f32::INFINITY, 0usize, 0usize);
        let mut right_cost = [0f32; MAX_BINS];
        for axis in (0..3).filter(|&a| usable(a)) {
            let bins = &bins[axis][..k];
            let mut acc = Box3::EMPTY;
            let mut count = 0u32;
            let mut cost = f32::INFINITY;
            for i in (1..k).rev() {
                if bins[i].count > 0 {
                    acc = acc.union(bins[i].b);
                    count += bins[i].count;
                    cost = acc.half_area() * count as f32;
                }
                right_cost[i - 1] = cost;
            }
            let mut acc = Box3::EMPTY;
            let mut count = 0u32;
            for (i, bin) in bins[..k - 1].iter().enumerate() {
                if bin.count == 0 {
                    continue;
                }
                acc = acc.union(bin.b);
                count += bin.count;
                let cost = acc.half_area() * count as f32 + right_cost[i];
                if cost < best.0 {
                    best = (cost, axis, i);
                }
            }
        }
        let (cost, axis, bin) = best;
        if !cost.is_finite() {
            return None;
        }
        let area = rb.bounds.half_area();
        let split_cost = self.traversal_cost * area + self.intersection_cost * cost;
        let leaf_cost = self.intersection_cost * area * n as f32;
        if split_cost >= leaf_cost && n <= self.max_leaf_size {
            return None;
        }
        // Both sides' boxes are the unions of their bins; centroid bounds are gathered while
        // partitioning by the bins noted during binning.
        let bins = &bins[axis][..k];
        let union = |b: &[Bin]| b.iter().fold(Box3::EMPTY, |acc, b| acc.union(b.b));
        let (lb, rb) = (union(&bins[..=bin]), union(&bins[bin + 1..]));
        let shift = 8 * axis as u32;
        let bin = bin as u32;
        let mut split = partition(refs, |r| (r.bins >> shift) & 0xff <= bin);
        split.left.bounds = lb;
        split.right.bounds = rb;
        Some(split)
    }
}

/// Partitions `refs` in place by `goes_left`, gathering both sides' centroid bounds on the way
/// (the boxes are left empty for the caller to fill).
fn partition(refs: &mut [PrimRef], goes_left: impl Fn(&PrimRef) -> bool) -> Split {
    let mut left = RangeBounds::EMPTY;
    let mut right = RangeBounds::EMPTY;
    let (mut i, mut j) = (0, refs.len());
    loop {
        while i < j && goes_left(&refs[i]) {
            left.add_centroid(&refs[i]);
            i += 1;
        }
        while i < j && !goes_left(&refs[j - 1]) {
            right.add_centroid(&refs[j - 1]);
            j -= 1;
        }
        if i >= j {
            break;
        }
        refs.swap(i, j - 1);
    }
    Split {
        mid: i,
        left,
        right,
    }
}
