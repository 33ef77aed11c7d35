//! Compressed copies of the wide nodes for single-ray traversal: each child box stored as 8-bit
//! plane offsets on a per-node grid, as in compressed wide BVHs (Ylitie, Karras & Laine,
//! "Efficient Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs", 2017), so that an
//! 8-wide node takes two cache lines instead of four.
//!
//! The grid step of each axis is a power of two and the grid origin a multiple of it, small
//! enough in steps that `origin + q * step` is exact in f32 for every `q` in `0..=255`: a
//! decoded plane is a plain f32 box coordinate, and the slab test on it is the exact-box test
//! of [`lanes::slab`](super::lanes::slab), so its conservativeness argument carries over. The
//! planes are rounded outward (min down, max up, checked on the decoded value), so every
//! decoded box holds its exact box and no hit is lost.

use super::WideNode;
use super::lanes::RayLanes;
use crate::geom::{Aabb, FAR_SCALE};
use glam::Vec3;
use wide::f32x8;

/// A node's child boxes on its grid, with its child references.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct QNode<const K: usize> {
    /// Grid origin per axis (a multiple of the step, at or below the node's box).
    origin: [f32; 3],
    /// Grid step per axis (a power of two).
    step: [f32; 3],
    /// A bit per lane that holds a child (empty lanes' planes are not meaningful).
    pub(super) occupied: u32,
    /// Plane offsets in steps: rows min x, y, z, max x, y, z; one lane per child.
    q: [[u8; K]; 6],
    /// Child references, as in [`WideNode::child`].
    pub(super) child: [u32; K],
}

/// The grid of one axis for the node box `[lo, hi]`: `(origin, step)`, or `None` when no
/// exact grid exists (a non-finite box, or coordinates near `f32::MAX`).
fn grid(lo: f32, hi: f32) -> Option<(f32, f32)> {
    if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
        return None;
    }
    // 254 steps span the box even after the origin is rounded down by up to one step; the
    // coordinates stay below 2^23 steps, so origin + q * step (an integer below 2^24 times a
    // power of two) is exact.
    let need = ((hi - lo) / 254.0).max(lo.abs().max(hi.abs()) * (1.0 / 8_388_608.0));
    let mut e = if need > 0.0 {
        need.log2().ceil() as i32
    } else {
        -126
    };
    e = e.max(-126);
    loop {
        if e > 118 {
            return None;
        }
        let step = f32::from_bits(((e + 127) as u32) << 23);
        let origin = (lo / step).floor() * step;
        // log2 and the divisions round: check the span and move up a step if it falls short.
        if origin <= lo && origin + 255.0 * step >= hi && (origin / step).abs() < 8_388_608.0 {
            return Some((origin, step));
        }
        e += 1;
    }
}

impl<const K: usize> QNode<K> {
    /// The compressed copy of `n`, or `None` when some axis has no exact grid.
    pub(super) fn encode(n: &WideNode<K>) -> Option<Self> {
        let b = n.bounds();
        let mut origin = [0f32; 3];
        let mut step = [0f32; 3];
        for a in 0..3 {
            (origin[a], step[a]) = grid(b.min[a], b.max[a])?;
        }
        let occupied = n.occupied();
        let mut q = [[0u8; K]; 6];
        for k in 0..K {
            if occupied & (1 << k) == 0 {
                // An inverted box, though the traversal masks empty lanes anyway.
                for a in 0..3 {
                    q[a][k] = 255;
                    q[a + 3][k] = 0;
                }
                continue;
            }
            for a in 0..3 {
                let (o, s) = (origin[a], step[a]);
                let dec = |v: u8| o + f32::from(v) * s;
                let lo = n.bounds[a][k];
                let hi = n.bounds[a + 3][k];
                let mut ql = ((lo - o) / s).floor().clamp(0.0, 255.0) as u8;
                while ql > 0 && dec(ql) > lo {
                    ql -= 1;
                }
                let mut qh = ((hi - o) / s).ceil().clamp(0.0, 255.0) as u8;
                while qh < 255 && dec(qh) < hi {
                    qh += 1;
                }
                debug_assert!(dec(ql) <= lo && dec(qh) >= hi);
                q[a][k] = ql;
                q[a + 3][k] = qh;
            }
        }
        Some(Self {
            origin,
            step,
            occupied,
            q,
            child: n.child,
        })
    }

    /// A node with no children.
    pub(super) const EMPTY: Self = Self {
        origin: [0.0; 3],
        step: [1.0; 3],
        occupied: 0,
        q: [[0; K]; 6],
        child: [super::EMPTY_CHILD; K],
    };

    /// The decoded box of lane `k`.
    pub(super) fn lane_box(&self, k: usize) -> Aabb {
        let d = |i: usize| self.origin[i % 3] + f32::from(self.q[i][k]) * self.step[i % 3];
        Aabb::new(Vec3::new(d(0), d(1), d(2)), Vec3::new(d(3), d(4), d(5)))
    }
}

/// [`lanes::slab`](super::lanes::slab) on a compressed node: the same arithmetic on the decoded
/// (exact) planes, masked to the occupied lanes.
#[inline(always)]
pub(super) fn slab_q<const K: usize>(
    n: &QNode<K>,
    r: &RayLanes,
    tmax: f32,
    dist: &mut [f32; K],
) -> u32 {
    if K == 8 {
        let plane = |i: usize| -> f32x8 {
            let a = i % 3;
            let q: &[u8; 8] = n.q[i].as_slice().try_into().expect("K == 8");
            f32x8::from(q.map(f32::from)) * f32x8::splat(n.step[a]) + f32x8::splat(n.origin[a])
        };
        let t = |a: usize, row: usize| {
            (plane(row) - f32x8::splat(r.origin[row])) * f32x8::splat(r.inv[a])
        };
        let tn = t(0, r.near[0])
            .fast_max(t(1, r.near[1]))
            .fast_max(t(2, r.near[2]).fast_max(f32x8::splat(r.tmin)));
        let tf = t(0, r.far[0])
            .fast_min(t(1, r.far[1]))
            .fast_min(t(2, r.far[2]).fast_min(f32x8::splat(tmax)))
            * f32x8::splat(FAR_SCALE);
        dist.as_mut_slice().copy_from_slice(&tn.to_array());
        tn.simd_le(tf).to_bitmask() & n.occupied
    } else {
        let mut bounds = [[0f32; K]; 6];
        for (i, row) in bounds.iter_mut().enumerate() {
            let a = i % 3;
            for k in 0..K {
                row[k] = n.origin[a] + f32::from(n.q[i][k]) * n.step[a];
            }
        }
        super::lanes::slab(&bounds, r, tmax, dist) & n.occupied
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grids_are_exact_and_span_the_box() {
        let cases = [
            (0.0, 0.0),
            (-1.0, 1.0),
            (1e-30, 2e-30),
            (1000.0, 1000.001),
            (-3.5e6, -3.4e6),
            (0.1, 0.1),
            (-1e30, 1e30),
        ];
        for (lo, hi) in cases {
            let (o, s) = grid(lo, hi).expect("finite");
            assert!(o <= lo && o + 255.0 * s >= hi, "{lo} {hi}: {o} {s}");
            for q in 0..=255u32 {
                let d = f64::from(o) + f64::from(q) * f64::from(s);
                assert_eq!(f64::from(o + q as f32 * s), d, "{lo} {hi} q {q}");
            }
        }
        assert!(grid(f32::NEG_INFINITY, 0.0).is_none());
        assert!(grid(-f32::MAX, f32::MAX).is_none());
    }
}
