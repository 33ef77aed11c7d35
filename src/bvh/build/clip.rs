//! Clip-aware build: one tree for a whole animation clip, after Bittner & Meister 2015
//! ("T-SAH: Animation optimized bounding volume hierarchies").
//!
//! A glTF clip is known in advance, so the tree's topology can be chosen for sampled poses of
//! it instead of the pose it is built at. The objective is the **mean over the sampled poses of
//! each pose's SAH** (areas normalised by that pose's root area, so every pose weighs the
//! same): each node's split minimises it greedily, as binned SAH minimises one pose's. The
//! candidates are binned splits of the centroids as they lie in each sampled pose (a split that
//! is good at one pose is tried against all of them); the tree's boxes are those of the pose
//! it is built at, so it is refitted from there like any other tree.

use super::{Box3, PrimRef, RangeBounds, Split, Splitter};
use crate::bvh::mesh::Indexed;
use crate::bvh::{BuildParams, BuildWorkspace, MeshBvh};
use glam::Vec3;

/// Bins per axis and sampled pose.
const BINS: usize = 16;

/// The sampled poses' triangle boxes, kept from one clip-aware build to the next so that a
/// rebuild allocates nothing once they have grown.
#[derive(Clone, Debug, Default)]
pub struct ClipPoses {
    /// `boxes[k][t]`: triangle `t`'s box in pose `k`.
    boxes: Vec<Vec<Box3>>,
    /// One over each pose's root half area (0 for a pose with no extent: it weighs nothing).
    inv_root: Vec<f64>,
}

impl ClipPoses {
    /// Bytes held.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        use crate::bvh::held;
        held(&self.boxes) + self.boxes.iter().map(held).sum::<usize>() + held(&self.inv_root)
    }

    /// Bounds every triangle in each pose of `poses` (vertex positions for `indices`).
    fn set(&mut self, poses: &[&[Vec3]], indices: &[[u32; 3]]) {
        self.boxes.resize_with(poses.len(), Vec::new);
        self.inv_root.clear();
        for (boxes, positions) in self.boxes.iter_mut().zip(poses) {
            let mesh = Indexed { positions, indices };
            boxes.clear();
            let mut root = Box3::EMPTY;
            for t in 0..mesh.len() {
                let (lo, hi) = mesh.triangle_corners(t);
                // The references' sanitizing: NaN skipped, infinities clamped.
                let r = PrimRef::from_corners(lo, hi, 0);
                let b = Box3 {
                    min: r.lo(),
                    max: r.hi(),
                };
                root = root.union(b);
                boxes.push(b);
            }
            let a = root.half_area_f64();
            self.inv_root.push(if a > 0.0 && a.is_finite() {
                1.0 / a
            } else {
                0.0
            });
        }
    }

    /// Poses that weigh something.
    fn weighted(&self) -> usize {
        self.inv_root.iter().filter(|&&w| w > 0.0).count()
    }
}

/// The splitter: binned SAH summed over the sampled poses.
pub(crate) struct ClipAware<'a> {
    poses: &'a ClipPoses,
    max_leaf: usize,
    traversal_cost: f64,
    intersection_cost: f64,
}

/// Per-task scratch: bins for every (pose binned in, axis, bin) with a box in every pose.
pub(crate) struct ClipScratch {
    b: ClipBufs,
    /// Cost of the right side from each bin on.
    right: [f64; BINS],
}

/// The buffers of a [`ClipScratch`], kept per thread from one task to the next.
#[derive(Default)]
struct ClipBufs {
    counts: Vec<u32>,
    boxes: Vec<Box3>,
    /// The node's box in every pose, and a running box per pose for the sweep.
    node: Vec<Box3>,
    acc: Vec<Box3>,
    /// Centroid bounds (doubled centroids) of the node in every pose.
    cbounds: Vec<Box3>,
}

thread_local! {
    /// Buffers of this thread's finished clip-aware build tasks, for its next ones: the
    /// engine's clip-aware rebuilds allocate nothing once each thread has as many as its
    /// tasks nest.
    static SPARE: std::cell::RefCell<Vec<ClipBufs>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Buffers a thread gets at its first clip-aware build task (more are made when tasks nest
/// deeper on it).
const SPARES: usize = 8;

impl ClipBufs {
    /// Buffers with room for `k` poses.
    fn for_poses(k: usize) -> Self {
        Self {
            counts: Vec::with_capacity(k * 3 * BINS),
            boxes: Vec::with_capacity(k * 3 * BINS * k),
            node: Vec::with_capacity(k),
            acc: Vec::with_capacity(k),
            cbounds: Vec::with_capacity(k),
        }
    }
}

impl Drop for ClipScratch {
    fn drop(&mut self) {
        let b = std::mem::take(&mut self.b);
        // Ignored while the thread is being torn down.
        let _ = SPARE.try_with(|p| p.borrow_mut().push(b));
    }
}

impl ClipAware<'_> {
    fn k(&self) -> usize {
        self.poses.boxes.len()
    }

    /// Sum over poses of each box's half area over its pose's root's.
    fn weighted_area(&self, boxes: &[Box3]) -> f64 {
        boxes
            .iter()
            .zip(&self.poses.inv_root)
            .map(|(b, w)| b.half_area_f64() * w)
            .sum()
    }
}

/// The bin of doubled centroid coordinate `c` on an axis whose centroids start at `lo`.
#[inline(always)]
fn bin_of(c: f32, lo: f32, scale: f32) -> usize {
    (((c - lo) * scale) as usize).min(BINS - 1)
}

impl Splitter for ClipAware<'_> {
    type Scratch = ClipScratch;

    fn scratch(&self) -> ClipScratch {
        let k = self.k();
        let mut b = SPARE.with_borrow_mut(|spare| {
            if spare.capacity() == 0 {
                // The thread's first clip-aware task: room for as many as nest on a thread
                // in practice, for the most poses, at once.
                spare.reserve_exact(SPARES);
                spare.extend((0..SPARES - 1).map(|_| ClipBufs::for_poses(MAX_POSES)));
                return ClipBufs::for_poses(MAX_POSES);
            }
            spare.pop().unwrap_or_else(|| ClipBufs::for_poses(k))
        });
        b.counts.resize(k * 3 * BINS, 0);
        b.boxes.resize(k * 3 * BINS * k, Box3::EMPTY);
        for v in [&mut b.node, &mut b.acc, &mut b.cbounds] {
            v.resize(k, Box3::EMPTY);
        }
        ClipScratch {
            b,
            right: [0.0; BINS],
        }
    }

    fn split(&self, refs: &mut [PrimRef], _: &RangeBounds, s: &mut ClipScratch) -> Option<Split> {
        let (k, n) = (self.k(), refs.len());
        // The node's box and centroid bounds in every pose.
        for j in 0..k {
            let (mut b, mut c) = (Box3::EMPTY, Box3::EMPTY);
            let boxes = &self.poses.boxes[j];
            for r in refs.iter() {
                let t = boxes[r.id() as usize];
                b = b.union(t);
                c.grow_point(t.min + t.max);
            }
            s.b.node[j] = b;
            s.b.cbounds[j] = c;
        }
        // Bin the centroids as they lie in each pose `f`, with boxes in every pose `j`.
        s.b.counts.fill(0);
        s.b.boxes.fill(Box3::EMPTY);
        let mut scales = [[0.0f32; 3]; MAX_POSES];
        let scales = &mut scales[..k];
        for (f, sc) in scales.iter_mut().enumerate() {
            let ext = s.b.cbounds[f].max - s.b.cbounds[f].min;
            for a in 0..3 {
                sc[a] = if ext[a] > 0.0 && ext[a].is_finite() {
                    BINS as f32 * (1.0 - 1e-6) / ext[a]
                } else {
                    0.0
                };
            }
        }
        for r in refs.iter() {
            let id = r.id() as usize;
            for (f, sc) in scales.iter().enumerate() {
                let t = self.poses.boxes[f][id];
                let c = t.min + t.max;
                let lo = s.b.cbounds[f].min;
                for a in 0..3 {
                    if sc[a] == 0.0 {
                        continue;
                    }
                    let bin = (f * 3 + a) * BINS + bin_of(c[a], lo[a], sc[a]);
                    s.b.counts[bin] += 1;
                    let at = bin * k;
                    for j in 0..k {
                        let b = &mut s.b.boxes[at + j];
                        let tj = self.poses.boxes[j][id];
                        b.grow(tj.min, tj.max);
                    }
                }
            }
        }
        // Sweep each (pose, axis): the least summed cost of the two sides.
        let mut best: Option<(f64, usize, usize, usize)> = None;
        for (f, sc) in scales.iter().enumerate() {
            for (a, &scale) in sc.iter().enumerate() {
                if scale == 0.0 {
                    continue;
                }
                let base = (f * 3 + a) * BINS;
                s.b.acc.fill(Box3::EMPTY);
                let mut count = 0u32;
                for b in (1..BINS).rev() {
                    count += s.b.counts[base + b];
                    for j in 0..k {
                        s.b.acc[j] = s.b.acc[j].union(s.b.boxes[(base + b) * k + j]);
                    }
                    s.right[b] = f64::from(count) * self.weighted_area(&s.b.acc);
                }
                s.b.acc.fill(Box3::EMPTY);
                let mut left = 0u32;
                for b in 0..BINS - 1 {
                    left += s.b.counts[base + b];
                    for j in 0..k {
                        s.b.acc[j] = s.b.acc[j].union(s.b.boxes[(base + b) * k + j]);
                    }
                    if left == 0 || left as usize == n {
                        continue;
                    }
                    let cost = f64::from(left) * self.weighted_area(&s.b.acc) + s.right[b + 1];
                    if best.is_none_or(|(c, ..)| cost < c) {
                        best = Some((cost, f, a, b + 1));
                    }
                }
            }
        }
        let (cost, f, a, at) = best?;
        let node = self.weighted_area(&s.b.node);
        let split_cost = self.traversal_cost * node + self.intersection_cost * cost;
        if n <= self.max_leaf && self.intersection_cost * n as f64 * node <= split_cost {
            return None;
        }
        // Partition by the chosen bin of pose `f`'s centroids.
        let (lo, sc) = (s.b.cbounds[f].min[a], scales[f][a]);
        let boxes = &self.poses.boxes[f];
        let goes_left = |r: &PrimRef| {
            let t = boxes[r.id() as usize];
            bin_of((t.min + t.max)[a], lo, sc) < at
        };
        let mut mid = 0;
        for i in 0..n {
            if goes_left(&refs[i]) {
                refs.swap(i, mid);
                mid += 1;
            }
        }
        if mid == 0 || mid == n {
            return None;
        }
        Some(Split {
            mid,
            left: RangeBounds::of(&refs[..mid], usize::MAX),
            right: RangeBounds::of(&refs[mid..], usize::MAX),
        })
    }
}

/// The most poses a clip-aware build weighs (each costs its share of every node's binning).
pub const MAX_POSES: usize = 8;

impl MeshBvh {
    /// A tree over the triangles at `positions` whose topology minimises the mean SAH over
    /// `poses` (vertex positions of the same mesh at sampled times of its clip; at most
    /// [`MAX_POSES`] are used, evenly chosen), to be refitted through the clip. With no pose
    /// that has an extent it is [`MeshBvh::build_indexed`]'s tree.
    ///
    /// # Panics
    /// When a vertex index is out of range for `positions` or a pose.
    #[must_use]
    pub fn build_clip_aware(
        positions: &[Vec3],
        indices: &[[u32; 3]],
        poses: &[&[Vec3]],
        params: &BuildParams,
    ) -> Self {
        let mut m = Self::default();
        m.rebuild_clip_aware(
            positions,
            indices,
            poses,
            params,
            &mut BuildWorkspace::one_shot(),
            &mut ClipPoses::default(),
        );
        m
    }

    /// [`MeshBvh::build_clip_aware`] into this tree, reusing its storage, `ws`'s and `clip`'s.
    ///
    /// # Panics
    /// As [`MeshBvh::build_clip_aware`].
    pub fn rebuild_clip_aware(
        &mut self,
        positions: &[Vec3],
        indices: &[[u32; 3]],
        poses: &[&[Vec3]],
        params: &BuildParams,
        ws: &mut BuildWorkspace,
        clip: &mut ClipPoses,
    ) {
        let mut picked: [&[Vec3]; MAX_POSES] = [&[]; MAX_POSES];
        let mut k = 0;
        for i in evenly(poses.len(), MAX_POSES) {
            picked[k] = poses[i];
            k += 1;
        }
        clip.set(&picked[..k], indices);
        if clip.weighted() == 0 {
            self.rebuild_indexed(positions, indices, params, ws);
            return;
        }
        let splitter = ClipAware {
            poses: clip,
            max_leaf: params.max_leaf_size.max(1) as usize,
            traversal_cost: f64::from(params.traversal_cost),
            intersection_cost: f64::from(params.intersection_cost),
        };
        self.rebuild_split(positions, indices, Some(&splitter), params, ws);
    }
}

/// At most `max` indices of `0..n`, evenly spread, first and last included.
fn evenly(n: usize, max: usize) -> impl Iterator<Item = usize> {
    let m = n.min(max);
    (0..m).map(move |i| if m <= 1 { 0 } else { i * (n - 1) / (m - 1) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn evenly_spreads_and_keeps_the_ends() {
        assert_eq!(evenly(3, 8).collect::<Vec<_>>(), vec![0, 1, 2]);
        assert_eq!(evenly(30, 4).collect::<Vec<_>>(), vec![0, 9, 19, 29]);
        assert_eq!(evenly(1, 4).collect::<Vec<_>>(), vec![0]);
        assert_eq!(evenly(0, 4).count(), 0);
    }
}
