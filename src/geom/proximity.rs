//! Point, box and sphere tests against triangles, for the proximity and overlap queries: the
//! closest point of a triangle to a point (Voronoi regions of the vertices, edges and face, as
//! in Ericson, *Real-Time Collision Detection*, 2005, §5.1.5), the triangle/box separating
//! axis test (Akenine-Möller, "Fast 3D triangle-box overlap testing", 2001), and the distance
//! from a point to a box with a margin that keeps tree pruning conservative under rounding.

use super::Aabb;
use glam::Vec3;

/// The point of triangle `a b c` closest to `p`. A degenerate triangle (a segment or a point)
/// gives the closest point of its edges; a non-finite vertex may give a non-finite point, whose
/// distance then compares false with everything (callers keep the nearest by `<`).
#[must_use]
#[inline]
pub fn closest_point_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let w = d1 / (d1 - d3);
        return a + ab * w;
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return a + ac * w;
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return b + (c - b) * w;
    }
    let denom = va + vb + vc;
    if denom.is_nan() || denom <= 0.0 || !denom.is_finite() {
        return closest_on_edges(p, a, b, c);
    }
    let v = vb / denom;
    let w = vc / denom;
    a + ab * v + ac * w
}

/// The closest point to `p` on the three edges of `a b c` (for degenerate triangles).
fn closest_on_edges(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let on = |s: Vec3, e: Vec3| {
        let d = e - s;
        let len = d.length_squared();
        let w = if len > 0.0 {
            ((p - s).dot(d) / len).clamp(0.0, 1.0)
        } else {
            0.0
        };
        s + d * w
    };
    let mut best = on(a, b);
    for q in [on(b, c), on(c, a)] {
        if q.distance_squared(p) < best.distance_squared(p) {
            best = q;
        }
    }
    best
}

/// A lower bound of the squared distance from `p` to any point of `b` as computed in f32 by
/// [`closest_point_on_triangle`] for a triangle inside `b`: the box is widened by a few ulps of
/// its coordinates first, so rounding in the triangle's closest point (which may land an ulp or
/// two outside the triangle's box) never makes a tree prune a node that holds the nearest
/// triangle. `+inf` for an empty box.
#[must_use]
#[inline(always)]
pub fn box_distance_squared(p: Vec3, b: Aabb) -> f32 {
    let pad = (b.min.abs().max(b.max.abs()) + p.abs()) * (8.0 * f32::EPSILON);
    let lo = b.min - pad;
    let hi = b.max + pad;
    let d = (lo - p).max(p - hi).max(Vec3::ZERO);
    // An empty box has min > max on some axis: both differences are then positive, the
    // distance finite; empty boxes are kept out by the callers' checks.
    let d2 = d.length_squared();
    if d2.is_nan() { f32::INFINITY } else { d2 }
}

/// True when triangle `a b c` and box `bx` share a point (faces and edges included; a
/// triangle with a non-finite vertex touches nothing, nor does a box with a NaN coordinate,
/// which holds no point): the
/// separating axis test over the box's three axes, the triangle's normal and the nine cross
/// products of box axes and triangle edges.
#[must_use]
pub fn triangle_overlaps_box(a: Vec3, b: Vec3, c: Vec3, bx: Aabb) -> bool {
    // The box axes: exactly the triangle's box against the query box.
    let tmin = a.min(b).min(c);
    let tmax = a.max(b).max(c);
    if !(tmin.is_finite() && tmax.is_finite()) || bx.min.is_nan() || bx.max.is_nan() {
        return false;
    }
    if tmin.cmpgt(bx.max).any() || tmax.cmplt(bx.min).any() {
        return false;
    }
    let centre = (bx.min + bx.max) * 0.5;
    let h = (bx.max - bx.min) * 0.5;
    let v0 = a - centre;
    let v1 = b - centre;
    let v2 = c - centre;
    let e = [v1 - v0, v2 - v1, v0 - v2];
    // Tolerance for the rounding of the projections: an axis separates only by more than it.
    let scale = v0.abs().max(v1.abs()).max(v2.abs()).max(h).max_element();
    let tol = scale * scale * (16.0 * f32::EPSILON);
    let separates = |axis: Vec3| {
        let p0 = axis.dot(v0);
        let p1 = axis.dot(v1);
        let p2 = axis.dot(v2);
        let r = h.x * axis.x.abs() + h.y * axis.y.abs() + h.z * axis.z.abs();
        p0.min(p1).min(p2) > r + tol || p0.max(p1).max(p2) < -r - tol
    };
    for edge in e {
        for unit in [Vec3::X, Vec3::Y, Vec3::Z] {
            let axis = unit.cross(edge);
            if axis != Vec3::ZERO && separates(axis) {
                return false;
            }
        }
    }
    let n = e[0].cross(e[1]);
    !(n != Vec3::ZERO && separates(n))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_point_regions() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        assert_eq!(
            closest_point_on_triangle(Vec3::new(-1.0, -1.0, 0.0), a, b, c),
            a
        );
        assert_eq!(
            closest_point_on_triangle(Vec3::new(2.0, -1.0, 0.0), a, b, c),
            b
        );
        assert_eq!(
            closest_point_on_triangle(Vec3::new(0.5, -1.0, 3.0), a, b, c),
            Vec3::new(0.5, 0.0, 0.0)
        );
        assert_eq!(
            closest_point_on_triangle(Vec3::new(0.25, 0.25, 5.0), a, b, c),
            Vec3::new(0.25, 0.25, 0.0)
        );
        // The hypotenuse.
        let q = closest_point_on_triangle(Vec3::new(1.0, 1.0, 0.0), a, b, c);
        assert!((q - Vec3::new(0.5, 0.5, 0.0)).length() < 1e-6);
        // Degenerate: a segment.
        let q = closest_point_on_triangle(Vec3::new(0.5, 1.0, 0.0), a, b, b * 0.5);
        assert!((q - Vec3::new(0.5, 0.0, 0.0)).length() < 1e-6);
    }

    #[test]
    fn triangle_box_cases() {
        let (a, b, c) = (
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 2.0, 0.0),
        );
        let unit = |o: Vec3| Aabb::new(o, o + Vec3::splat(0.5));
        assert!(triangle_overlaps_box(
            a,
            b,
            c,
            unit(Vec3::new(0.2, 0.2, -0.25))
        ));
        // Inside the triangle's box, beyond the hypotenuse.
        assert!(!triangle_overlaps_box(
            a,
            b,
            c,
            unit(Vec3::new(1.2, 1.2, -0.25))
        ));
        // Above the plane.
        assert!(!triangle_overlaps_box(
            a,
            b,
            c,
            unit(Vec3::new(0.2, 0.2, 0.1))
        ));
        // Touching the plane with a face.
        assert!(triangle_overlaps_box(
            a,
            b,
            c,
            unit(Vec3::new(0.2, 0.2, 0.0))
        ));
    }

    #[test]
    fn box_distance_is_a_lower_bound() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        assert_eq!(box_distance_squared(Vec3::splat(0.5), b), 0.0);
        let d = box_distance_squared(Vec3::new(3.0, 0.5, 0.5), b);
        assert!(d <= 4.0 && d > 3.99);
    }
}
