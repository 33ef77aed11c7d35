//! Conservative ray intervals for the space partitions (kd-tree, octree, grid) and the BIH.
//!
//! A node's interval `[tn, tf]` always contains the distances over which the exact ray lies in
//! the node's cell: distances to planes are widened by [`PLANE_SLACK`] (more than the three
//! roundings of `(plane - origin) * inv_dir`), so a cell the ray touches is never skipped. A
//! traversal that keeps every hit it finds (never only those inside the current cell) may then
//! stop once the best hit lies before every cell still to visit; since two triangles through
//! one point compute slightly different `t`, that test allows [`HIT_SLACK`] more. A leaf may
//! skip a triangle whose box the ray misses over the leaf's interval ([`SlabRay`]), widened
//! the same way.

use crate::geom::{FAR_SCALE, Ray};
use glam::{Vec3, Vec3A};

/// Relative widening of a plane distance: `2^-20`, about five times the rounding of
/// `(plane - origin) * inv_dir` (three operations of `2^-24` each).
pub(super) const PLANE_SLACK: f32 = 1.0 / (1u32 << 20) as f32;

/// Relative margin between a hit's computed distance and the cells it may lie in: a node is
/// skipped only when it starts beyond the best hit by more than this (`2^-16`).
pub(super) const HIT_SLACK: f32 = 1.0 / (1u32 << 16) as f32;

/// `x` moved down by [`PLANE_SLACK`] of itself (infinities and zeros stay). The slack takes
/// `x`'s sign, so that no branch depends on it.
#[inline(always)]
pub(super) fn lower(x: f32) -> f32 {
    x * (1.0 - PLANE_SLACK.copysign(x))
}

/// `x` moved up by [`PLANE_SLACK`] of itself (infinities and zeros stay).
#[inline(always)]
pub(super) fn upper(x: f32) -> f32 {
    x * (1.0 + PLANE_SLACK.copysign(x))
}

/// The distance beyond which a node cannot hold a hit closer than `best`.
#[inline(always)]
pub(super) fn beyond(best: f32) -> f32 {
    if best > 0.0 {
        best * (1.0 + HIT_SLACK)
    } else {
        best * (1.0 - HIT_SLACK)
    }
}

/// `a.min(b)` for an `a` that is not NaN: one instruction, where `f32::min` also looks for a
/// NaN `a` (a NaN `b` gives `a`, as there).
#[inline(always)]
pub(super) fn min_of(a: f32, b: f32) -> f32 {
    if b < a { b } else { a }
}

/// `a.max(b)` for an `a` that is not NaN (see [`min_of`]).
#[inline(always)]
pub(super) fn max_of(a: f32, b: f32) -> f32 {
    if b > a { b } else { a }
}

/// The ray's distance to the plane `x[axis] = plane` (`±inf` or NaN when it runs parallel).
#[inline(always)]
pub(super) fn plane_distance(ray: &Ray, axis: usize, plane: f32) -> f32 {
    // Through the vectors' arrays: `Vec3`'s run-time index is a `match` per access.
    let (o, inv): (&[f32; 3], &[f32; 3]) = (ray.origin.as_ref(), ray.inv_dir.as_ref());
    (plane - o[axis]) * inv[axis]
}

/// Conservative entry and exit distances of the ray through the box `[lo, hi]` within
/// `[ray.tmin, tmax]`, or `None` when it misses (the slab test of [`Ray::hit_box`], with the
/// entry lowered as the exit is raised).
#[inline]
pub(super) fn box_interval(ray: &Ray, lo: Vec3, hi: Vec3, tmax: f32) -> Option<(f32, f32)> {
    let t0 = (lo - ray.slab_lo) * ray.inv_dir;
    let t1 = (hi - ray.slab_hi) * ray.inv_dir;
    let near = t0.min(t1);
    let far = t0.max(t1);
    let tn = lower(near.max_element()).max(ray.tmin);
    let tf = (far.min_element() * FAR_SCALE).min(tmax);
    let tf = upper(tf).min(tmax);
    (tn <= tf).then_some((tn, tf))
}

/// How the ray's interval `[tn, tf]` splits at a plane, the children named by the side the ray
/// reaches first (`near`: the lower side when it moves up the axis, or does not move along it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Crossing {
    /// Only the near side, over the same interval.
    Near,
    /// Only the far side, over the same interval.
    Far,
    /// Both: the near side up to the first distance, the far side from the second.
    Both(f32, f32),
}

/// The [`Crossing`] at distance `d` to the plane (the course's rule, widened: `d > tf` near
/// only, `d < tn` far only, else both). A NaN distance (the ray lies in the plane) is both,
/// over the whole interval: no comparison with NaN holds, and `min`/`max` return the other side.
#[inline(always)]
pub(super) fn cross(d: f32, tn: f32, tf: f32) -> Crossing {
    let (lo, hi) = (lower(d), upper(d));
    if tn > hi {
        Crossing::Far
    } else if lo > tf {
        Crossing::Near
    } else {
        Crossing::Both(hi.min(tf), lo.max(tn))
    }
}

/// True when the ray moves towards the upper side of `axis` (or does not move along it): the
/// lower side is then the near one.
#[inline(always)]
pub(super) fn lower_is_near(ray: &Ray, axis: usize) -> bool {
    let inv: &[f32; 3] = ray.inv_dir.as_ref();
    inv[axis] > 0.0
}

/// Bit `a` set when the upper side of `axis` `a` is the near one ([`lower_is_near`] false):
/// walks that split on one axis a node take their near child from it by arithmetic, with no
/// branch on the node's axis.
#[inline(always)]
pub(super) fn upper_near_bits(ray: &Ray) -> u32 {
    (0..3).map(|a| u32::from(!lower_is_near(ray, a)) << a).sum()
}

/// What the triangle box test reads of a ray, in SIMD lanes: the slab test's origins and the
/// reciprocal direction.
#[derive(Clone, Copy)]
pub(super) struct SlabRay {
    lo: Vec3A,
    hi: Vec3A,
    inv: Vec3A,
}

impl SlabRay {
    #[inline(always)]
    pub(super) fn new(ray: &Ray) -> Self {
        Self {
            lo: ray.slab_lo.into(),
            hi: ray.slab_hi.into(),
            inv: ray.inv_dir.into(),
        }
    }

    /// Calls `visit(i, &items[i])` for each item of a leaf whose triangle (`corners(item)`)
    /// the ray over `[tn, tf]` (the leaf's widened interval) may meet, in order, until it
    /// returns true (then returns true). The box tests of 32 items at a time run first,
    /// without a branch, into a bit mask (a branch per triangle would often mispredict).
    #[inline(always)]
    pub(super) fn each_met<T>(
        &self,
        items: &[T],
        corners: impl Fn(&T) -> &[Vec3; 3],
        (tn, tf): (f32, f32),
        mut visit: impl FnMut(usize, &T) -> bool,
    ) -> bool {
        for (k, chunk) in items.chunks(32).enumerate() {
            let mut keep = 0u32;
            for (i, item) in chunk.iter().enumerate() {
                keep |= u32::from(self.meets_box(corners(item), tn, tf)) << i;
            }
            while keep != 0 {
                let i = keep.trailing_zeros() as usize;
                keep &= keep - 1;
                if visit(32 * k + i, &chunk[i]) {
                    return true;
                }
            }
        }
        false
    }

    /// Whether the ray over `[tn, tf]` may meet the box of `tri`'s corners: the slab test of
    /// [`box_interval`], widened the same way, on SIMD lanes with plain `min`/`max` (one
    /// instruction each, like `Ray::hit_box`). A NaN can only make the answer "may meet": it
    /// drops out of a `min` or `max`, or of the choice against `tn` and `tf` (a looser bound).
    /// The one exception, a lane with one NaN distance and one finite, comes from a ray that
    /// does not move on that axis and a box face one ulp off its origin (see `Ray::slab_lo`):
    /// the ray misses that box, and a triangle with a NaN coordinate, whose box may come out
    /// wrong, is never hit by the watertight test either.
    #[inline(always)]
    pub(super) fn meets_box(&self, tri: &[Vec3; 3], tn: f32, tf: f32) -> bool {
        let (a, b, c) = (
            Vec3A::from(tri[0]),
            Vec3A::from(tri[1]),
            Vec3A::from(tri[2]),
        );
        let t0 = (a.min(b).min(c) - self.lo) * self.inv;
        let t1 = (a.max(b).max(c) - self.hi) * self.inv;
        let near = lower(t0.min(t1).max_element());
        let far = upper(t0.max(t1).min_element() * FAR_SCALE);
        let near = if near > tn { near } else { tn };
        let far = if far < tf { far } else { tf };
        near <= far
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::{RayTriPrecomp, intersect_triangle};

    #[test]
    fn crossing_follows_the_course_rule() {
        assert_eq!(cross(5.0, 1.0, 2.0), Crossing::Near);
        assert_eq!(cross(0.5, 1.0, 2.0), Crossing::Far);
        assert_eq!(cross(-3.0, 0.0, 2.0), Crossing::Far);
        let Crossing::Both(a, b) = cross(1.5, 1.0, 2.0) else {
            panic!("both")
        };
        assert!(a >= 1.5 && b <= 1.5 && a < 1.6 && b > 1.4);
        assert!(matches!(
            cross(f32::NAN, 1.0, 2.0),
            Crossing::Both(2.0, 1.0)
        ));
        assert_eq!(cross(f32::INFINITY, 1.0, 2.0), Crossing::Near);
        assert_eq!(cross(f32::NEG_INFINITY, 1.0, 2.0), Crossing::Far);
        assert!(lower(3.0) < 3.0 && upper(3.0) > 3.0 && lower(-3.0) < -3.0);
        assert_eq!(lower(f32::INFINITY), f32::INFINITY);
    }

    #[test]
    fn box_interval_contains_the_slab_test() {
        let r = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X);
        let (tn, tf) = box_interval(&r, Vec3::ZERO, Vec3::ONE, f32::INFINITY).unwrap();
        assert!(tn <= 1.0 && tf >= 2.0 && tn > 0.99 && tf < 2.01);
        assert!(box_interval(&r, Vec3::ZERO, Vec3::ONE, 0.5).is_none());
    }

    /// Every hit the watertight test reports inside an interval is kept by `meets_box` over
    /// that interval, also for rays along an axis and intervals that end just past the hit.
    #[test]
    fn triangle_box_test_keeps_every_hit() {
        let mut seed = 0x2545_f491_u64;
        let mut next = move || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            ((seed >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        };
        let mut hits = 0;
        for i in 0..20_000 {
            let tri = [(); 3].map(|()| Vec3::new(next(), next(), next()));
            let origin = Vec3::new(next(), next(), next()) * 3.0;
            let mut dir =
                (tri[0] + tri[1] + tri[2]) / 3.0 - origin + Vec3::new(next(), next(), next()) * 0.3;
            if i % 4 == 0 {
                // Along one axis only.
                let a = i / 4 % 3;
                dir = Vec3::ZERO;
                dir[a] = if next() > 0.0 { 1.0 } else { -1.0 };
            }
            let ray = Ray::new(origin, dir);
            let slab = SlabRay::new(&ray);
            let pre = RayTriPrecomp::new(ray.dir);
            let Some((t, _, _)) =
                intersect_triangle(&ray, &pre, tri[0], tri[1], tri[2], f32::INFINITY)
            else {
                continue;
            };
            hits += 1;
            let (below, above) = (t * (1.0 - 1.0 / 4096.0), t * (1.0 + 1.0 / 4096.0));
            for (tn, tf) in [
                (0.0, f32::INFINITY),
                (below, above),
                (0.0, above),
                (below, 2.0 * t),
            ] {
                assert!(slab.meets_box(&tri, tn, tf), "ray {i}: hit at {t} dropped");
            }
        }
        assert!(hits > 1000, "{hits} hits");
    }
}
