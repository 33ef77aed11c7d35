//! A cheap estimate of the SAH cost a fresh build would reach now, so that a refitted tree's
//! degradation is measured against what a rebuild would give, not against the tree as it was
//! at its last build.
//!
//! The estimate is the SAH cost of a quick binned build (8 bins on the widest centroid axis,
//! no nodes written) over a fixed subsample of the triangles: every `n / K`-th triangle, with
//! `K` at most [`FreshSah::MAX_SAMPLE`] and about an eighth of the mesh for large ones. Its
//! absolute value differs from a full build's (fewer, differently sized leaves), so it is
//! calibrated at every (re)build: `fresh(f) ~ SAH(b) * est(f) / est(b)`, where `b` is the frame
//! of the last build. On `animations/explode.glb` a fresh tree's cost falls while the
//! refitted one rises; this ratio follows the fall, the last-build ratio does not.
//!
//! The scratch buffer is sized once: estimating allocates nothing.

use crate::geom::Aabb;
use glam::{Vec3, Vec3A};

/// Bins per split of the quick build.
const BINS: usize = 8;
/// Deepest recursion; below it a range becomes a leaf (its cost counts as such).
const MAX_DEPTH: u32 = 48;

#[derive(Clone, Copy, Debug)]
struct Ref {
    lo: Vec3A,
    hi: Vec3A,
}

impl Ref {
    #[inline(always)]
    fn c2(&self) -> Vec3A {
        self.lo + self.hi
    }
}

#[derive(Clone, Copy, Debug)]
struct Bounds {
    lo: Vec3A,
    hi: Vec3A,
}

impl Bounds {
    const EMPTY: Bounds = Bounds {
        lo: Vec3A::splat(f32::INFINITY),
        hi: Vec3A::splat(f32::NEG_INFINITY),
    };

    #[inline(always)]
    fn grow(&mut self, lo: Vec3A, hi: Vec3A) {
        self.lo = self.lo.min(lo);
        self.hi = self.hi.max(hi);
    }

    #[inline(always)]
    fn half_area(&self) -> f32 {
        let e = (self.hi - self.lo).max(Vec3A::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }
}

/// The subsample and scratch of one mesh's fresh-build estimate.
#[derive(Clone, Debug, Default)]
pub struct FreshSah {
    /// Triangle indices sampled.
    sample: Vec<u32>,
    /// Boxes of the sampled triangles, reordered by the quick build.
    refs: Vec<Ref>,
    max_leaf: usize,
}

impl FreshSah {
    /// Bytes held.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        use crate::bvh::held;
        held(&self.sample) + held(&self.refs)
    }

    /// The largest subsample.
    pub const MAX_SAMPLE: usize = 4096;
    /// Meshes up to this many triangles are sampled whole, and larger ones by at least this
    /// many: a smaller sample misses morphs that move only part of a mesh of about a thousand
    /// triangles (`docs/internals.md`, "Constants and the runs behind them").
    pub const WHOLE: usize = 1024;

    /// The subsample for a mesh of `triangles` triangles, leaves of at most `max_leaf`.
    #[must_use]
    pub fn new(triangles: usize, max_leaf: u32) -> Self {
        let k = if triangles <= Self::WHOLE {
            triangles
        } else {
            (triangles / 16).clamp(Self::WHOLE, Self::MAX_SAMPLE)
        };
        Self::with_sample(triangles, k, max_leaf)
    }

    /// A subsample of `k` triangles (at most all) of a mesh of `triangles`.
    #[must_use]
    pub fn with_sample(triangles: usize, k: usize, max_leaf: u32) -> Self {
        let k = k.min(triangles);
        let sample = (0..k).map(|j| (j * triangles / k.max(1)) as u32).collect();
        Self {
            sample,
            refs: vec![
                Ref {
                    lo: Vec3A::ZERO,
                    hi: Vec3A::ZERO
                };
                k
            ],
            max_leaf: max_leaf.max(1) as usize,
        }
    }

    /// Triangles sampled.
    #[must_use]
    pub fn sample_len(&self) -> usize {
        self.sample.len()
    }

    /// SAH cost of the quick build over the sampled triangles at these positions (both
    /// constants 1, normalised by the sample's root area). Comparable only with other
    /// estimates of the same mesh.
    pub fn estimate(&mut self, positions: &[Vec3], indices: &[[u32; 3]]) -> f32 {
        let mut root = Bounds::EMPTY;
        let mut cb = Bounds::EMPTY;
        for (r, &t) in self.refs.iter_mut().zip(&self.sample) {
            let [a, b, c] = indices[t as usize];
            let tri = [
                positions[a as usize],
                positions[b as usize],
                positions[c as usize],
            ];
            let bx = Aabb::of_triangle(&tri).sanitized();
            let (lo, hi) = if bx.is_empty() {
                (Vec3A::ZERO, Vec3A::ZERO)
            } else {
                (Vec3A::from(bx.min), Vec3A::from(bx.max))
            };
            *r = Ref { lo, hi };
            root.grow(lo, hi);
            cb.grow(lo + hi, lo + hi);
        }
        let n = self.refs.len();
        if n == 0 {
            return 0.0;
        }
        let area = root.half_area();
        if !(area > 0.0 && area.is_finite()) {
            return n as f32;
        }
        let sum = cost(&mut self.refs, root, cb, self.max_leaf, 0);
        (sum / f64::from(area)) as f32
    }
}

/// Unnormalised SAH cost (interior areas plus leaf areas times counts) of a quick binned build
/// over `refs`, whose box is `b` and doubled-centroid box `cb`.
fn cost(refs: &mut [Ref], b: Bounds, cb: Bounds, max_leaf: usize, depth: u32) -> f64 {
    let n = refs.len();
    let area = f64::from(b.half_area());
    let leaf = area * n as f64;
    if n <= 1 || depth >= MAX_DEPTH {
        return leaf;
    }
    let ext = cb.hi - cb.lo;
    let axis = if ext.x >= ext.y && ext.x >= ext.z {
        0
    } else if ext.y >= ext.z {
        1
    } else {
        2
    };
    let (lo, w) = (cb.lo[axis], ext[axis]);
    let split = if w > 0.0 && w.is_finite() {
        binned_split(refs, axis, lo, w)
    } else {
        None
    };
    let mid = match split {
        Some((mid, split_cost)) => {
            if n <= max_leaf && leaf <= area + split_cost {
                return leaf;
            }
            mid
        }
        None if n <= max_leaf => return leaf,
        // Centroids all in one place: halve by count.
        None => n / 2,
    };
    let (l, r) = refs.split_at_mut(mid);
    let (lb, lc) = bounds_of(l);
    let (rb, rc) = bounds_of(r);
    area + cost(l, lb, lc, max_leaf, depth + 1) + cost(r, rb, rc, max_leaf, depth + 1)
}

fn bounds_of(refs: &[Ref]) -> (Bounds, Bounds) {
    let mut b = Bounds::EMPTY;
    let mut c = Bounds::EMPTY;
    for r in refs {
        b.grow(r.lo, r.hi);
        let c2 = r.c2();
        c.grow(c2, c2);
    }
    (b, c)
}

#[inline(always)]
fn bin_of(c: f32, lo: f32, scale: f32) -> usize {
    (((c - lo) * scale) as usize).min(BINS - 1)
}

/// Bins `refs` on `axis` and partitions them at the cheapest bin boundary: `(left count, SAH
/// of the two sides)`, or `None` when every centroid lands in one bin.
fn binned_split(refs: &mut [Ref], axis: usize, lo: f32, w: f32) -> Option<(usize, f64)> {
    let scale = BINS as f32 * (1.0 - 1e-5) / w;
    let mut bins = [Bounds::EMPTY; BINS];
    let mut counts = [0usize; BINS];
    for r in refs.iter() {
        let k = bin_of(r.c2()[axis], lo, scale);
        bins[k].grow(r.lo, r.hi);
        counts[k] += 1;
    }
    // Sweep from the right: the area and count right of each boundary.
    let mut right_area = [0.0f64; BINS];
    let mut acc = Bounds::EMPTY;
    let mut cnt = 0;
    let mut right_count = [0usize; BINS];
    for k in (1..BINS).rev() {
        acc.grow(bins[k].lo, bins[k].hi);
        cnt += counts[k];
        right_area[k] = f64::from(acc.half_area());
        right_count[k] = cnt;
    }
    let mut acc = Bounds::EMPTY;
    let mut cnt = 0;
    let mut best: Option<(usize, f64)> = None;
    for k in 1..BINS {
        acc.grow(bins[k - 1].lo, bins[k - 1].hi);
        cnt += counts[k - 1];
        if cnt == 0 || right_count[k] == 0 {
            continue;
        }
        let c = f64::from(acc.half_area()) * cnt as f64 + right_area[k] * right_count[k] as f64;
        if best.is_none_or(|(_, b)| c < b) {
            best = Some((k, c));
        }
    }
    let (k, c) = best?;
    // Partition: bins below k to the left.
    let mut i = 0;
    let mut j = refs.len();
    while i < j {
        if bin_of(refs[i].c2()[axis], lo, scale) < k {
            i += 1;
        } else {
            j -= 1;
            refs.swap(i, j);
        }
    }
    Some((i, c))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize, spread: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut p = Vec::new();
        let mut t = Vec::new();
        for k in 0..n {
            let o = Vec3::new((k % 17) as f32, (k / 17) as f32, 0.0) * spread;
            let b = p.len() as u32;
            p.extend([o, o + Vec3::X * 0.5, o + Vec3::Y * 0.5]);
            t.push([b, b + 1, b + 2]);
        }
        (p, t)
    }

    #[test]
    fn spreading_triangles_apart_lowers_the_estimate() {
        let (p, t) = grid(2000, 1.0);
        let mut e = FreshSah::new(t.len(), 8);
        assert_eq!(e.sample_len(), FreshSah::WHOLE);
        let near = e.estimate(&p, &t);
        let far_p: Vec<Vec3> = {
            let (q, _) = grid(2000, 4.0);
            q
        };
        let far = e.estimate(&far_p, &t);
        assert!(near > 1.0 && far > 1.0);
        assert!(far < near, "far {far} near {near}");
        // Same positions, same estimate.
        assert_eq!(e.estimate(&p, &t), near);
    }

    #[test]
    fn degenerate_inputs() {
        let mut e = FreshSah::new(0, 8);
        assert_eq!(e.estimate(&[], &[]), 0.0);
        let p = vec![Vec3::ONE; 3];
        let t = vec![[0, 1, 2]; 40];
        let mut e = FreshSah::new(t.len(), 4);
        assert_eq!(e.estimate(&p, &t), 40.0);
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::splat(f32::NAN)];
        let mut e = FreshSah::new(1, 4);
        assert!(e.estimate(&p, &[[0, 1, 2]]).is_finite());
    }
}
