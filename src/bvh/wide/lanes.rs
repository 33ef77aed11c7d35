//! The SIMD kernels of the wide tree: the slab test of one ray against all `K` child boxes of a
//! node at once, and the union of a node's child boxes. Written with the `wide` crate (AVX or
//! SSE when the target has them, plain arrays otherwise), so there is no `unsafe` here.

use crate::geom::{Aabb, FAR_SCALE, Ray};
use glam::Vec3;
use wide::{f32x4, f32x8};

/// Per-ray constants of the slab test: which of a node's six bound rows is the near and the far
/// plane on each axis (by the sign of the reciprocal direction), origin and reciprocal.
#[derive(Clone, Copy, Debug)]
pub(super) struct RayLanes {
    origin: [f32; 3],
    inv: [f32; 3],
    tmin: f32,
    near: [usize; 3],
    far: [usize; 3],
}

impl RayLanes {
    #[inline(always)]
    pub(super) fn new(ray: &Ray) -> Self {
        let mut near = [0, 1, 2];
        let mut far = [3, 4, 5];
        for a in 0..3 {
            // A negative reciprocal (also `-f32::MAX` for a `-0.0` component) enters through
            // the max plane. For a box with min <= max this gives exactly the distances of
            // `Ray::hit_box` (which takes min/max of the two); an inverted (empty) box misses.
            if ray.inv_dir[a].is_sign_negative() {
                near[a] = 3 + a;
                far[a] = a;
            }
        }
        Self {
            origin: ray.origin.into(),
            inv: ray.inv_dir.into(),
            tmin: ray.tmin,
            near,
            far,
        }
    }
}

/// Tests the ray against the `K` boxes `bounds` (rows min x, y, z, max x, y, z; one lane per
/// child) within `[tmin, tmax]`. Returns the mask of hit lanes (bit `i` for lane `i`) and writes
/// every lane's entry distance into `dist`. Lane by lane the same arithmetic as
/// [`Ray::hit_box`], so just as conservative and NaN-free.
#[inline(always)]
pub(super) fn slab<const K: usize>(
    bounds: &[[f32; K]; 6],
    r: &RayLanes,
    tmax: f32,
    dist: &mut [f32; K],
) -> u32 {
    if K == 8 {
        let row = |i: usize| -> f32x8 {
            let a: &[f32; 8] = bounds[i].as_slice().try_into().expect("K == 8");
            f32x8::from(*a)
        };
        let t = |a: usize, plane: usize| {
            (row(plane) - f32x8::splat(r.origin[a])) * f32x8::splat(r.inv[a])
        };
        let tn = t(0, r.near[0])
            .fast_max(t(1, r.near[1]))
            .fast_max(t(2, r.near[2]).fast_max(f32x8::splat(r.tmin)));
        let tf = t(0, r.far[0])
            .fast_min(t(1, r.far[1]))
            .fast_min(t(2, r.far[2]).fast_min(f32x8::splat(tmax)))
            * f32x8::splat(FAR_SCALE);
        dist.as_mut_slice().copy_from_slice(&tn.to_array());
        tn.simd_le(tf).to_bitmask()
    } else if K == 4 {
        let row = |i: usize| -> f32x4 {
            let a: &[f32; 4] = bounds[i].as_slice().try_into().expect("K == 4");
            f32x4::from(*a)
        };
        let t = |a: usize, plane: usize| {
            (row(plane) - f32x4::splat(r.origin[a])) * f32x4::splat(r.inv[a])
        };
        let tn = t(0, r.near[0])
            .fast_max(t(1, r.near[1]))
            .fast_max(t(2, r.near[2]).fast_max(f32x4::splat(r.tmin)));
        let tf = t(0, r.far[0])
            .fast_min(t(1, r.far[1]))
            .fast_min(t(2, r.far[2]).fast_min(f32x4::splat(tmax)))
            * f32x4::splat(FAR_SCALE);
        dist.as_mut_slice().copy_from_slice(&tn.to_array());
        tn.simd_le(tf).to_bitmask()
    } else {
        let mut mask = 0;
        for i in 0..K {
            let t = |a: usize, plane: usize| (bounds[plane][i] - r.origin[a]) * r.inv[a];
            let tn = fmax(
                fmax(t(0, r.near[0]), t(1, r.near[1])),
                fmax(t(2, r.near[2]), r.tmin),
            );
            let tf = fmin(
                fmin(t(0, r.far[0]), t(1, r.far[1])),
                fmin(t(2, r.far[2]), tmax),
            ) * FAR_SCALE;
            dist[i] = tn;
            mask |= u32::from(tn <= tf) << i;
        }
        mask
    }
}

#[inline(always)]
fn fmax(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

#[inline(always)]
fn fmin(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// The union of a node's `K` child boxes (empty lanes hold the empty box).
#[inline(always)]
pub(super) fn union_lanes<const K: usize>(bounds: &[[f32; K]; 6]) -> Aabb {
    let lo = |i: usize| bounds[i].iter().fold(f32::INFINITY, |m, &v| fmin(m, v));
    let hi = |i: usize| bounds[i].iter().fold(f32::NEG_INFINITY, |m, &v| fmax(m, v));
    Aabb::new(
        Vec3::new(lo(0), lo(1), lo(2)),
        Vec3::new(hi(3), hi(4), hi(5)),
    )
}
