//! Kernels of packet traversal: 16 rays at a time (`wide::f32x16`: one AVX-512 register, two
//! AVX ones, or plain arrays without either), the slab test and the watertight triangle test.
//!
//! Every lane computes exactly the operations of the single-ray code, in the same order and
//! without fused multiply-adds: the slab test of [`crate::geom::Ray::hit_box`] and the shear and
//! edge functions of [`crate::geom::intersect_triangle`] (Woop, Benthin & Wald 2013). A lane
//! whose edge function is exactly zero is reported in [`TriHits::redo`] so that the caller
//! repeats it with the scalar test (which redoes such edges in f64): the packet then reports
//! bit for bit the distance and barycentrics a single ray does.

use crate::geom::FAR_SCALE;
use glam::Vec3;
use wide::f32x16;

/// Rays per SIMD group.
pub const LANES: usize = 16;

type F = f32x16;

/// 16 rays in structure-of-arrays form, with the per-ray constants of the watertight test.
#[derive(Clone, Copy, Debug)]
pub struct RayLanes {
    /// Origin the slab test subtracts from a box's lower corner ([`Ray::slab_lo`]), per axis.
    pub slab_lo: [F; 3],
    /// Origin the slab test subtracts from a box's upper corner ([`Ray::slab_hi`]), per axis.
    pub slab_hi: [F; 3],
    /// Reciprocal direction (zero components as `+inf`, as [`Ray`] keeps it).
    pub inv: [F; 3],
    /// Start of each ray's interval.
    pub tmin: F,
    /// End of each ray's interval: shrinks to the closest hit found so far.
    pub tmax: F,
    /// Origin permuted by the ray's `(kx, ky, kz)`.
    pub ok: [F; 3],
    /// Shear constants `sx, sy, sz`.
    pub s: [F; 3],
    /// Masks: `kx == 0`, `kx == 1`, `ky == 0`, `ky == 1`, `kz == 0`, `kz == 1`.
    pub k: [F; 6],
}

impl Default for RayLanes {
    fn default() -> Self {
        let z = F::splat(0.0);
        let one = F::splat(1.0);
        Self {
            slab_lo: [z; 3],
            slab_hi: [z; 3],
            inv: [one; 3],
            tmin: z,
            tmax: F::splat(f32::NEG_INFINITY),
            ok: [z; 3],
            s: [z; 3],
            k: [z; 6],
        }
    }
}

/// What one triangle test of 16 lanes found.
#[derive(Clone, Copy, Debug)]
pub struct TriHits {
    /// Lanes hit within `[tmin, tmax)` (among those asked).
    pub hit: u32,
    /// Lanes with an edge function of exactly zero or an overflowing scaled distance: repeat
    /// them with the scalar test.
    pub redo: u32,
    /// The lanes of a hit as a vector mask: exactly `hit` when `exact` is true.
    pub mask: F,
    /// True when `mask` holds exactly the lanes of `hit` (none outside `ask`, none redone).
    pub exact: bool,
    /// Distance of each hit lane.
    pub t: F,
    /// Barycentric weight of the second vertex.
    pub u: F,
    /// Barycentric weight of the third vertex.
    pub v: F,
}

/// A triangle's vertices with their coordinates in the rays' permuted order: `[vertex][kx, ky,
/// kz]`, one value per lane.
pub type PermutedTri = [[F; 3]; 3];

impl RayLanes {
    /// The slab test of every lane against `[bmin, bmax]` from `tmin` to `tmax`, closed: bit
    /// `i` is set when lane `i` touches the box (conservative as [`Ray::hit_box`]).
    #[inline(always)]
    #[must_use]
    pub fn hit_box(&self, bmin: [f32; 3], bmax: [f32; 3]) -> u32 {
        let mut tn = self.tmin;
        let mut tf = self.tmax;
        for a in 0..3 {
            let t0 = (F::splat(bmin[a]) - self.slab_lo[a]) * self.inv[a];
            let t1 = (F::splat(bmax[a]) - self.slab_hi[a]) * self.inv[a];
            tn = tn.fast_max(t0.fast_min(t1));
            tf = tf.fast_min(t0.fast_max(t1));
        }
        tn.simd_le(tf * F::splat(FAR_SCALE)).to_bitmask()
    }

    /// The triangle's vertices permuted lane by lane by each ray's `(kx, ky, kz)`.
    #[inline(always)]
    #[must_use]
    pub fn permute(&self, tri: &[Vec3; 3]) -> PermutedTri {
        // Written out rather than with `array::map`, which is not always inlined.
        let one = |p: Vec3| {
            let (x, y, z) = (F::splat(p.x), F::splat(p.y), F::splat(p.z));
            let pick = |is0: F, is1: F| is0.select(x, is1.select(y, z));
            [
                pick(self.k[0], self.k[1]),
                pick(self.k[2], self.k[3]),
                pick(self.k[4], self.k[5]),
            ]
        };
        [one(tri[0]), one(tri[1]), one(tri[2])]
    }

    /// The triangle's vertices permuted by `(kx, ky, kz)`, the same for every lane.
    #[inline(always)]
    #[must_use]
    pub fn permute_uniform(tri: &[Vec3; 3], k: [usize; 3]) -> PermutedTri {
        // Through an array: `Vec3`'s run-time index is a `match` per access.
        let one = |p: Vec3| {
            let p = p.to_array();
            [F::splat(p[k[0]]), F::splat(p[k[1]]), F::splat(p[k[2]])]
        };
        [one(tri[0]), one(tri[1]), one(tri[2])]
    }

    /// The watertight test of every lane against one triangle (vertices permuted for the
    /// lanes), within `[tmin, tmax)` of each lane. Only lanes of `ask` are reported.
    #[inline(always)]
    #[must_use]
    pub fn hit_triangle(&self, tri: &PermutedTri, ask: u32) -> TriHits {
        let [okx, oky, okz] = self.ok;
        let [sx, sy, sz] = self.s;
        // Translate (v - origin, per component, as the scalar test does), then shear.
        let rel = |p: &[F; 3]| (p[0] - okx, p[1] - oky, p[2] - okz);
        let (a0, a1, a2) = rel(&tri[0]);
        let (b0, b1, b2) = rel(&tri[1]);
        let (c0, c1, c2) = rel(&tri[2]);
        let ax = a0 - sx * a2;
        let ay = a1 - sy * a2;
        let bx = b0 - sx * b2;
        let by = b1 - sy * b2;
        let cx = c0 - sx * c2;
        let cy = c1 - sy * c2;
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let zero = F::splat(0.0);
        let redo = (u.simd_eq(zero) | v.simd_eq(zero) | w.simd_eq(zero)).to_bitmask() & ask;
        let neg = u.simd_lt(zero) | v.simd_lt(zero) | w.simd_lt(zero);
        let pos = u.simd_gt(zero) | v.simd_gt(zero) | w.simd_gt(zero);
        let outside = neg & pos;
        let inside = !outside.to_bitmask() & ask & !redo;
        if inside == 0 {
            return TriHits {
                hit: 0,
                redo,
                mask: zero,
                exact: true,
                t: zero,
                u: zero,
                v: zero,
            };
        }
        let det = u + v + w;
        let az = sz * a2;
        let bz = sz * b2;
        let cz = sz * c2;
        let t_scaled = u * az + v * bz + w * cz;
        let rcp = F::splat(1.0) / det;
        let t = t_scaled * rcp;
        let det_ok = det.simd_ne(zero) & det.is_finite();
        // A scaled distance that is not a normal f32 (overflowed or underflowed) gives no hit
        // here (its `t` is not finite, or wrong); the scalar test redoes it in f64, as
        // `scaled_t_in_range` decides.
        let a = t_scaled.abs();
        let normal = a.simd_ge(F::splat(f32::MIN_POSITIVE)) & a.simd_lt(F::splat(f32::INFINITY));
        let ok = det_ok & normal & t.simd_ge(self.tmin) & t.simd_lt(self.tmax);
        let mask = ok & !outside;
        let all = mask.to_bitmask();
        let hit = all & inside;
        let overflow = (det_ok & !normal).to_bitmask() & inside;
        TriHits {
            hit,
            redo: redo | overflow,
            mask,
            exact: all == hit,
            t,
            u: v * rcp,
            v: w * rcp,
        }
    }
}
