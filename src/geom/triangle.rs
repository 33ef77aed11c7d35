//! Watertight ray/triangle intersection (Woop, Benthin & Wald, "Watertight Ray/Triangle
//! Intersection", JCGT 2013).
//!
//! The ray is translated to the origin and sheared so that it points along +z; the triangle's
//! vertices are transformed the same way and the 2D edge functions decide the hit. Two
//! triangles that share an edge compute that edge's function from the same transformed vertices,
//! so a ray through the shared edge or vertex hits at least one of them: nothing slips through.

use super::Ray;
use glam::Vec3;

/// Per-ray constants of the watertight test: the axis permutation and the shear.
#[derive(Clone, Copy, Debug)]
pub struct RayTriPrecomp {
    pub(crate) kx: usize,
    pub(crate) ky: usize,
    pub(crate) kz: usize,
    pub(crate) sx: f32,
    pub(crate) sy: f32,
    pub(crate) sz: f32,
}

impl RayTriPrecomp {
    /// Computes the permutation (`kz` = dimension of largest |dir|, winding kept) and shear.
    #[must_use]
    #[inline]
    pub fn new(dir: Vec3) -> Self {
        let a = dir.abs();
        let d = dir.to_array();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let sz = 1.0 / d[kz];
        Self {
            kx,
            ky,
            kz,
            sx: d[kx] * sz,
            sy: d[ky] * sz,
            sz,
        }
    }
}

/// Intersects `ray` (with its precomputed `pre`) with the triangle `v0 v1 v2` over
/// `[ray.tmin, tmax)`. Returns `(t, u, v)` with `u`, `v` the barycentric weights of `v1` and `v2`.
/// Both faces count; a ray in the triangle's plane misses.
#[must_use]
#[inline(always)]
pub fn intersect_triangle(
    ray: &Ray,
    pre: &RayTriPrecomp,
    v0: Vec3,
    v1: Vec3,
    v2: Vec3,
    tmax: f32,
) -> Option<(f32, f32, f32)> {
    let (kx, ky, kz) = (pre.kx, pre.ky, pre.kz);
    // As arrays: indexing a `Vec3` by a run-time axis is a `match` per access.
    let a = (v0 - ray.origin).to_array();
    let b = (v1 - ray.origin).to_array();
    let c = (v2 - ray.origin).to_array();
    let ax = a[kx] - pre.sx * a[kz];
    let ay = a[ky] - pre.sy * a[kz];
    let bx = b[kx] - pre.sx * b[kz];
    let by = b[ky] - pre.sy * b[kz];
    let cx = c[kx] - pre.sx * c[kz];
    let cy = c[ky] - pre.sy * c[kz];

    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    // An edge function that is exactly zero may hide the true sign: redo it in f64, which is
    // exact for products of f32 values.
    if u == 0.0 || v == 0.0 || w == 0.0 {
        u = (cx as f64 * by as f64 - cy as f64 * bx as f64) as f32;
        v = (ax as f64 * cy as f64 - ay as f64 * cx as f64) as f32;
        w = (bx as f64 * ay as f64 - by as f64 * ax as f64) as f32;
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let az = pre.sz * a[kz];
    let bz = pre.sz * b[kz];
    let cz = pre.sz * c[kz];
    let t_scaled = u * az + v * bz + w * cz;
    // The range test uses the divided t, the very value reported, so that which of two nearly
    // equal hits is the closest never depends on the order they were tested in.
    let rcp = 1.0 / det;
    let t = if scaled_t_in_range(t_scaled) {
        t_scaled * rcp
    } else {
        // The scaled distance is a cube of the coordinates: for coordinates past the cube root
        // of `f32::MAX` it overflows, below the cube root of the smallest normal f32 it
        // underflows (to a subnormal of a few bits, or to 0: a hit at the origin), although the
        // distance does neither. Redone in f64, where it cannot.
        scaled_t_f64(u, v, w, det, [az, bz, cz])
    };
    if !(t >= ray.tmin && t < tmax) {
        return None;
    }
    Some((t, v * rcp, w * rcp))
}

/// True when a scaled distance is a normal f32 (neither overflowed nor underflowed): else the
/// distance is redone by [`scaled_t_f64`]. Exactly 0 is redone too (it costs a hit through the
/// ray's origin a slower path, and a product that underflowed to 0 reports the true distance).
#[inline(always)]
pub(crate) fn scaled_t_in_range(t_scaled: f32) -> bool {
    let a = t_scaled.abs();
    (f32::MIN_POSITIVE..f32::INFINITY).contains(&a)
}

/// `(u az + v bz + w cz) / det` in f64, rounded to f32 once: the distance of a hit whose
/// scaled distance overflows or underflows f32 ([`scaled_t_in_range`]).
#[cold]
#[inline(never)]
pub(crate) fn scaled_t_f64(u: f32, v: f32, w: f32, det: f32, z: [f32; 3]) -> f32 {
    let t = f64::from(u) * f64::from(z[0])
        + f64::from(v) * f64::from(z[1])
        + f64::from(w) * f64::from(z[2]);
    (t / f64::from(det)) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hit(o: Vec3, d: Vec3, t: [Vec3; 3]) -> Option<(f32, f32, f32)> {
        let r = Ray::new(o, d);
        intersect_triangle(&r, &RayTriPrecomp::new(d), t[0], t[1], t[2], f32::INFINITY)
    }

    #[test]
    fn hits_inside_and_reports_barycentrics() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let (t, u, v) = hit(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z, tri).unwrap();
        assert_eq!(t, 1.0);
        assert!((u - 0.25).abs() < 1e-6 && (v - 0.25).abs() < 1e-6);
        // Back face too.
        assert!(hit(Vec3::new(0.25, 0.25, -1.0), Vec3::Z, tri).is_some());
        // Outside.
        assert!(hit(Vec3::new(0.75, 0.75, 1.0), -Vec3::Z, tri).is_none());
        // Behind the origin.
        assert!(hit(Vec3::new(0.25, 0.25, 1.0), Vec3::Z, tri).is_none());
    }

    #[test]
    fn far_and_huge_triangles_report_their_distance() {
        // At 1e15 the scaled distance (a cube of the coordinates) overflows f32; at 1e-10 it
        // is of the order of 1e-30, at 1e-13 a subnormal, at 1e-15 it underflows to 0. All
        // report the distance.
        for s in [1e-17f32, 1e-15, 1e-13, 1e-10, 1.0, 1e13, 1e15, 1e18] {
            let tri = [Vec3::ZERO, Vec3::X * s, Vec3::Y * s];
            let (t, u, v) = hit(Vec3::new(0.25, 0.25, 3.0) * s, -Vec3::Z, tri).unwrap();
            assert!((t / (3.0 * s) - 1.0).abs() < 1e-6, "scale {s}: t = {t}");
            assert!(
                (u - 0.25).abs() < 1e-5 && (v - 0.25).abs() < 1e-5,
                "scale {s}"
            );
        }
    }

    #[test]
    fn shared_edge_is_hit_by_one_of_the_pair() {
        // Two triangles of a quad share the diagonal; a ray through its midpoint hits one of them.
        let a = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0)];
        let b = [Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        for &o in &[Vec3::new(0.5, 0.5, 1.0), Vec3::new(0.3, 0.3, -2.0)] {
            let d = Vec3::new(o.x, o.y, 0.0) - o;
            assert!(hit(o, d, a).is_some() || hit(o, d, b).is_some());
        }
    }

    #[test]
    fn ray_in_plane_and_degenerate_triangle_miss() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        assert!(hit(Vec3::new(-1.0, 0.2, 0.0), Vec3::X, tri).is_none());
        let flat = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
        assert!(hit(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z, flat).is_none());
    }
}
