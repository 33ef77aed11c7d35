//! Perfect splits (Havran 2000; Wald & Havran 2006, section 4.3): the box a triangle has in a
//! cell is the box of the triangle clipped to the cell, not its own box clipped to the cell.
//! On a curved surface the two differ most in the small cells near the leaves, where a
//! triangle's box overlaps cells the triangle never enters; with the clipped box those cells
//! lose the reference, and cells beside the surface become empty and can be cut off.
//!
//! The clip is conservative: the cell is widened by a margin far above the rounding of the
//! clip (`2^-16` of the triangle's largest coordinate), and the result widened by it again,
//! then cut to the triangle's own box and the cell. A triangle is dropped from a cell only
//! when it misses the widened cell.

use crate::geom::Aabb;
use glam::Vec3;

/// Relative margin of the clip, against the triangle's largest coordinate.
const CLIP_MARGIN: f32 = 1.0 / (1u32 << 16) as f32;

/// At most 3 corners plus one per clip plane (6).
const MAX_CORNERS: usize = 9;

/// A convex polygon's corners.
struct Polygon {
    p: [Vec3; MAX_CORNERS],
    n: usize,
}

impl Polygon {
    /// Keeps the part of the polygon where `sign * (x[axis] - plane) <= 0` (Sutherland &
    /// Hodgman 1974, one plane).
    fn clip(&self, axis: usize, plane: f32, sign: f32) -> Polygon {
        let mut out = Polygon {
            p: [Vec3::ZERO; MAX_CORNERS],
            n: 0,
        };
        for i in 0..self.n {
            let a = self.p[i];
            let b = self.p[(i + 1) % self.n];
            let (da, db) = (sign * (a[axis] - plane), sign * (b[axis] - plane));
            if da <= 0.0 {
                out.push(a);
            }
            if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
                let t = da / (da - db);
                let mut q = a + (b - a) * t;
                q[axis] = plane;
                out.push(q);
            }
        }
        out
    }

    fn push(&mut self, q: Vec3) {
        // A convex polygon cut by one plane gains at most one corner; the bound holds.
        if self.n < MAX_CORNERS {
            self.p[self.n] = q;
            self.n += 1;
        }
    }
}

/// The box of triangle `tri` (its own box `tri_box`) within `cell`, widened as the module says;
/// empty when the triangle misses the widened cell. A triangle with a coordinate that is not
/// finite gets its box clipped to the cell. (The builders use [`split_clipped_boxes`].)
#[cfg(test)]
pub(super) fn clipped_box(tri: &[Vec3; 3], tri_box: &Aabb, cell: &Aabb) -> Aabb {
    clip_with_margin(tri, tri_box, cell, true)
}

/// [`clipped_box`] without the margin: the part of the triangle in `cell` as computed, for
/// `validate` (a triangle must be in every leaf this is not empty for, beyond a plane).
pub(super) fn clipped_box_exact(tri: &[Vec3; 3], tri_box: &Aabb, cell: &Aabb) -> Aabb {
    clip_with_margin(tri, tri_box, cell, false)
}

/// The margin for `tri` (`None` when a coordinate is not finite).
fn margin_of(tri: &[Vec3; 3]) -> Option<f32> {
    if !tri.iter().all(|p| p.is_finite()) {
        return None;
    }
    let big = tri.iter().fold(0.0f32, |m, p| m.max(p.abs().max_element()));
    Some(big * CLIP_MARGIN + f32::MIN_POSITIVE)
}

/// `tri` clipped to `cell` widened by `eps` (only at the planes its box `tri_box` crosses).
fn clip_to_cell(tri: &[Vec3; 3], tri_box: &Aabb, cell: &Aabb, eps: f32) -> Polygon {
    let mut poly = Polygon {
        p: [Vec3::ZERO; MAX_CORNERS],
        n: 3,
    };
    poly.p[..3].copy_from_slice(tri);
    for axis in 0..3 {
        let lo = cell.min[axis] - eps;
        if tri_box.min[axis] < lo {
            poly = poly.clip(axis, lo, -1.0);
        }
        let hi = cell.max[axis] + eps;
        if tri_box.max[axis] > hi {
            poly = poly.clip(axis, hi, 1.0);
        }
        if poly.n == 0 {
            break;
        }
    }
    poly
}

/// The box of `poly` widened by `eps` and cut to `base`; empty when `poly` is.
fn widened_box(poly: &Polygon, eps: f32, base: &Aabb) -> Aabb {
    if poly.n == 0 {
        return Aabb::EMPTY;
    }
    let b = Aabb::from_points(&poly.p[..poly.n]);
    let out = Aabb::new(
        (b.min - Vec3::splat(eps)).max(base.min),
        (b.max + Vec3::splat(eps)).min(base.max),
    );
    if out.is_empty() { Aabb::EMPTY } else { out }
}

fn clip_with_margin(tri: &[Vec3; 3], tri_box: &Aabb, cell: &Aabb, margin: bool) -> Aabb {
    let base = super::events::clip_box(tri_box, cell);
    let Some(eps) = margin_of(tri).filter(|_| !base.is_empty()) else {
        return base;
    };
    let eps = if margin { eps } else { 0.0 };
    widened_box(&clip_to_cell(tri, tri_box, cell, eps), eps, &base)
}

/// The boxes of `tri` (own box `tri_box`, which crosses the plane) in the two halves of
/// `cell` cut at `pos` on `axis`, as [`clipped_box`] gives them but with one clip to the
/// widened cell, whose polygon is then cut by the plane (widened to each side).
pub(super) fn split_clipped_boxes(
    tri: &[Vec3; 3],
    tri_box: &Aabb,
    cell: &Aabb,
    axis: usize,
    pos: f32,
) -> (Aabb, Aabb) {
    let (mut left, mut right) = (*cell, *cell);
    left.max[axis] = pos;
    right.min[axis] = pos;
    let (lb, rb) = (
        super::events::clip_box(tri_box, &left),
        super::events::clip_box(tri_box, &right),
    );
    let Some(eps) = margin_of(tri) else {
        return (lb, rb);
    };
    let poly = clip_to_cell(tri, tri_box, cell, eps);
    (
        widened_box(&poly.clip(axis, pos + eps, 1.0), eps, &lb),
        widened_box(&poly.clip(axis, pos - eps, -1.0), eps, &rb),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clips_a_diagonal_triangle_to_a_corner_cell() {
        // The triangle x + y <= 1 in z = 0: its box is the unit square, but it misses the cell
        // [0.6, 1] x [0.6, 1] and only grazes the cell [0.5, 1] x [0, 0.5] near its corner.
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let tb = Aabb::of_triangle(&tri);
        let cell = Aabb::new(Vec3::new(0.6, 0.6, -1.0), Vec3::new(1.0, 1.0, 1.0));
        assert!(clipped_box(&tri, &tb, &cell).is_empty());
        let cell = Aabb::new(Vec3::new(0.5, 0.0, -1.0), Vec3::new(1.0, 0.5, 1.0));
        let b = clipped_box(&tri, &tb, &cell);
        assert!(b.min.x >= 0.5 && b.max.x >= 1.0 && b.min.y == 0.0);
        assert!(b.max.y >= 0.5 && b.max.y < 0.51, "{b:?}");
        assert_eq!((b.min.z, b.max.z), (0.0, 0.0));
        // Exact within the margin.
        let e = clipped_box_exact(&tri, &tb, &cell);
        assert!(b.contains(&e) && e.max.y <= 0.5 + 1e-6);
    }

    #[test]
    fn keeps_a_triangle_that_touches_the_cell() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let tb = Aabb::of_triangle(&tri);
        let cell = Aabb::new(Vec3::new(0.5, 0.5, -1.0), Vec3::new(1.0, 1.0, 1.0));
        let b = clipped_box(&tri, &tb, &cell);
        assert!(!b.is_empty() && b.min.x <= 0.5 && b.min.y <= 0.5);
        // The split clip gives each half's box, within the margin of clipping to the half.
        let whole = Aabb::new(Vec3::new(0.0, 0.0, -1.0), Vec3::ONE);
        let (l, r) = split_clipped_boxes(&tri, &tb, &whole, 0, 0.75);
        let (mut lc, mut rc) = (whole, whole);
        lc.max.x = 0.75;
        rc.min.x = 0.75;
        let (el, er) = (
            clipped_box_exact(&tri, &tb, &lc),
            clipped_box_exact(&tri, &tb, &rc),
        );
        assert!(l.contains(&el) && r.contains(&er), "{l:?} {r:?}");
        assert!(r.max.y < 0.26 && l.max.y == 1.0, "{l:?} {r:?}");
        let inf = [Vec3::ZERO, Vec3::new(f32::INFINITY, 0.0, 0.0), Vec3::Y];
        let ib = Aabb::of_triangle(&inf);
        assert_eq!(
            clipped_box(&inf, &ib, &cell),
            super::super::events::clip_box(&ib, &cell)
        );
    }
}
